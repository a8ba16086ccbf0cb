"""What the first screen and the report say of a run's time: mountings nobody waited at
are said so (a simulated run's virtual operator, --yes), never "0 s at the machine";
the whole run is from its journal's header to its end, every session of a resumed run
and the pause between them, not the last session's wall time."""

from __future__ import annotations

import json
import time
from pathlib import Path

import pytest
from fakes import FakeRig, fake_config, resume_on, run_on
from result_builders import golden_result

from station.errors import RunFailed
from station.record.io import read_result
from station.record.journal_file import JOURNAL_NAME
from station.record.result import RunResult
from station.report import first_screen, render_html


def _result(**timing: float | None) -> RunResult:
    doc = golden_result()  # a simulated run, the whole run 402.3 s
    doc["timing"].update(timing)
    return RunResult.model_validate(doc)


def _real(result: RunResult) -> RunResult:
    return result.model_copy(update={"simulation": None})


@pytest.mark.parametrize("operator_s,simulated,words", [
    (0.0, True, "{n} (mounted by the simulator: nobody waited)"),
    (0.004, False, "{n} (answered by --yes: nobody waited at the machine)"),
    (95.0, False, "{n}, 1 min 35 s at the machine"),
    (12.5, False, "{n}, 12.5 s at the machine"),
])
def test_mountings_say_who_answered_and_how_long_they_took(
        operator_s: float, simulated: bool, words: str) -> None:
    result = _result(operator_s=operator_s)
    words = words.format(n=result.timing.mountings)  # the golden run's mountings
    result = result if simulated else _real(result)
    text = first_screen.timing_text(result)
    assert text is not None and text.startswith(words + ";"), text
    assert "0 s at the machine" not in text
    page = render_html(result, figures=False)
    assert f"mountings {words}" in page and "0 s at the machine" not in page


def test_the_whole_run_is_its_duration_not_the_last_sessions_wall_time() -> None:
    # resumed: 402.3 s from the header to the end, the last session 19 s of it
    text = first_screen.timing_text(_result(wall_s=19.0))
    assert text is not None and text.endswith("; the whole run 6 min 42 s"), text
    page = render_html(_result(wall_s=19.0), figures=False)
    assert "19.0 s (its last session)" in page


def test_a_resumed_run_lasts_from_its_header_to_its_end(tmp_path: Path) -> None:
    # The first session stopped by an alarm; its header moved 100 s back, as if it had
    # started 100 s before the resume: the whole run counts them, the session does not.
    config = fake_config(cycles=2, readings=2, settle_s=0.0, max_extra_passes=0,
                         model="rho")
    rig = FakeRig(true_drho=(0.4, -0.3, 0.2))
    rig.axes.alarm_on_move = 7
    with pytest.raises(RunFailed, match="alarm"):
        run_on(rig, tmp_path, config)
    (run_dir,) = tmp_path.glob("run-*")
    journal = run_dir / JOURNAL_NAME
    lines = journal.read_text().splitlines(keepends=True)
    header = json.loads(lines[0])
    assert header["type"] == "header"
    header["t"] -= 100.0
    journal.write_text(json.dumps(header) + "\n" + "".join(lines[1:]))
    rig.axes.reset_alarm()
    resumed_at = time.time()
    code, doc = resume_on(rig, run_dir, config)
    assert code == 0, doc.get("message")
    session = time.time() - resumed_at
    assert 100.0 <= doc["duration_s"] <= 100.0 + session + 60.0  # the first session's too
    assert doc["timing"]["wall_s"] <= session
    text = first_screen.timing_text(read_result(run_dir / "result.json"))
    assert text is not None
    minutes, seconds = _min_s(text)
    assert 100 <= 60 * minutes + seconds <= round(doc["duration_s"]) + 1


def _min_s(text: str) -> tuple[int, int]:
    """The whole run's "M min SS s" of a first screen's mountings line."""
    whole = text.split("the whole run ")[1]
    minutes, _, rest = whole.partition(" min ")
    return int(minutes), int(rest.removesuffix(" s"))
