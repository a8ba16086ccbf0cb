"""Every shipped example ends as its comment says: a file whose comment names a
command (``# Run:``) ends with the exit status and first line it states
(tests/helpers/stated_runs.py); the rest are run by the test their comment names. The
rehearsal runs once, in tests/station/report/test_first_screen.py (half a minute)."""

from __future__ import annotations

from pathlib import Path

import pytest
from builders import cli
from stated_runs import EXAMPLES, ROOT, stated

#: The test that runs each shipped example (its comment names it too).
RUN_BY = {
    "rehearsal.toml": "tests/station/report/test_first_screen.py",
    "station.toml": "tests/station/commands/test_examples.py",
    "maps/gateway-3x1.toml": "tests/drivers/test_your_drive.py",
    "maps/gateway-3x1-no-offsets.toml": "tests/drivers/test_your_drive.py",
    "linuxcnc/orthoglide.ini": "tests/station/history/test_linuxcnc.py",
    "linuxcnc/orthoglide.hal": "tests/station/history/test_linuxcnc.py",
}


def shipped() -> list[str]:
    return sorted(str(p.relative_to(EXAMPLES)) for p in EXAMPLES.rglob("*") if p.is_file())


def test_every_example_is_run_by_a_test_that_names_it() -> None:
    assert shipped() == sorted(RUN_BY), "a new example needs a test that runs it (RUN_BY)"
    for name, test in RUN_BY.items():
        path = ROOT / test
        assert path.is_file(), test
        assert Path(name).name in path.read_text(encoding="utf-8"), (name, test)

@pytest.mark.parametrize("name", [n for n in sorted(RUN_BY)
                                  if RUN_BY[n] == "tests/station/commands/test_examples.py"])
def test_the_example_ends_as_its_comment_says(name: str, tmp_path: Path) -> None:
    said = stated(EXAMPLES / name)
    assert said is not None, f"{name}: its comment names no command (# Run:)"
    done = cli(*said.argv, cwd=tmp_path)
    assert said.ends_so(done.returncode, done.stdout, done.stderr) is None, \
        said.ends_so(done.returncode, done.stdout, done.stderr)
    assert "Traceback" not in done.stderr and "internal error" not in done.stderr
