"""Make the golden run again: ``python tests/helpers/make_golden.py``.

tests/data/golden_run/ holds what one seeded, noise-free simulated run writes
(tests/station/engine/test_unchanged.py's ``seeded_run``): result.json, journal.jsonl, report.html
and plan.txt, with what cannot repeat taken out (times, the run directory, ports).
test_unchanged compares every run of the same seed with them, so that a change of
behaviour is seen and made on purpose. Run this only when a change of the result,
the journal, the report or the plan is intended, and say in the commit what changed
and why; the diff of these files is the review of that change.
"""

from __future__ import annotations

import json
import shutil
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "station" / "engine"))

from test_unchanged import (  # noqa: E402 (after the path: runnable as a script)
    GOLDEN,
    normal_html,
    normal_journal,
    normal_result,
    seeded_run,
)


def main() -> None:
    with tempfile.TemporaryDirectory(prefix="orthocal-golden-") as tmp:
        run_dir = seeded_run(Path(tmp))
        result = normal_result(json.loads((run_dir / "result.json").read_text()))
        (GOLDEN / "result.json").write_text(
            json.dumps(result, indent=1, sort_keys=True, ensure_ascii=True) + "\n")
        journal = normal_journal((run_dir / "journal.jsonl").read_text())
        (GOLDEN / "journal.jsonl").write_text(
            "".join(json.dumps(r, sort_keys=True) + "\n" for r in journal))
        (GOLDEN / "report.html").write_text(
            normal_html((run_dir / "report.html").read_text(), str(run_dir)))
        shutil.copyfile(run_dir / "plan.txt", GOLDEN / "plan.txt")
    print(f"golden run written to {GOLDEN}")


if __name__ == "__main__":
    main()
