"""A plunger guard stop says what moved under the mounting and names the likely cause
(station.engine.guard_words), never "nothing has moved" after a cycle moved the axes,
nor preload where the gauge reads against its configured direction."""

from __future__ import annotations

from pathlib import Path

import pytest
from builders import FAST, station_config
from fakes import FakeRig, run_on

from station.commands.simulate.launch import SIM_PROCEDURE
from station.engine.guard_words import AxesSeen, likely_cause, reversed_evidence
from station.errors import RunFailed
from station.plan.guard import GuardedGauge, MoveRecord


def _gauge(preload: float = 0.3, stroke: float = 2.0) -> GuardedGauge:
    return GuardedGauge("B", "z", -preload, stroke - preload, baseline=5.0)


def test_what_moved_names_each_axis_from_where_to_where() -> None:
    seen = AxesSeen()
    seen.at([(310.25, 310.25, 310.25), (370.25, 300.0, 310.25), (210.25, 310.25, 310.25)])
    text = seen.text((310.25, 310.25, 310.25))
    assert "axis x moved between +210.250 and +370.250 mm" in text
    assert "y moved between +300.000 and +310.250 mm" in text
    assert "z did not move (+310.250 mm)" in text
    assert text.endswith("the axes stand at x +310.250, y +310.250, z +310.250 mm")
    assert AxesSeen().text() == "the axes have not moved under this mounting"


def test_a_gauge_reading_against_its_direction_is_named_not_the_preload() -> None:
    # the nominal travel over two moves, and the gauge's: the same size, the other sign
    against = [MoveRecord("Π_x^+", travel={"B": (-0.31, 0.0)}, nominal={"B": (0.0, 0.30)}),
               MoveRecord("Π_x^-", travel={"B": (0.0, 0.19)}, nominal={"B": (-0.2, 0.0)})]
    along = [MoveRecord("Π_x^+", travel={"B": (0.0, 0.29)}, nominal={"B": (0.0, 0.30)})]
    assert reversed_evidence(against, "B") and not reversed_evidence(along, "B")
    text = likely_cause(_gauge(), False, against, {}, 0.3)
    assert "'-z'" in text and "not the preload" in text
    # moves too short to tell (the nominal travel within the noise): no such claim
    short = [MoveRecord("Π0", travel={"B": (-0.01, 0.0)}, nominal={"B": (0.0, 0.01)})]
    assert not reversed_evidence(short, "B")


def test_the_cause_is_the_machines_error_or_the_preload_as_the_stops_show() -> None:
    big = {"0": {"B": 0.0}, "+": {"B": -0.45}}  # 0.45 mm at a test posture
    text = likely_cause(_gauge(), False, [], big, 0.3)
    assert "the machine's own error" in text and "0.450 mm" in text
    assert "more preload" in text
    small = {"0": {"B": 0.0}, "+": {"B": 0.01}}
    text = likely_cause(_gauge(), True, [], small, 0.3)
    assert "more preload than the config's preload_mm = 0.3 mm" in text
    assert "re-mount it with less preload" in text


class _Reversed(FakeRig):
    """Gauge B mounted the other way round from what the config says."""

    def mount(self, name: str, leg: str, direction: str, at: float = 0.5) -> None:
        if name == "B":
            direction = direction[1:] if direction.startswith("-") else "-" + direction
        super().mount(name, leg, direction, at)


def test_a_stop_after_the_first_cycle_says_what_moved_and_why(tmp_path: Path) -> None:
    # 0.3 mm of preload on a 2 mm gauge, joint offsets of up to 2 mm: the first cycle
    # moves leg x's axes, then the guard refuses what comes next.
    indicators = [{"name": n, "port": f"/dev/{n.lower()}", "stroke_mm": 2.0,
                   "preload_mm": 0.3} for n in "AB"]
    config = station_config(controller={"motion": "coordinated"},
                            procedure={**SIM_PROCEDURE, **FAST, "model": "rho"},
                            writeback={"max_abs_offset_mm": 3.0}, report={"figures": False},
                            history={"enabled": False}, indicators=indicators)
    rig = _Reversed(seed=1, noise_mm=0.001, true_drho=(2.0, -1.8, 1.5))
    with pytest.raises(RunFailed) as stop:
        run_on(rig, tmp_path / "runs", config)
    text = str(stop.value)
    assert "plunger guard" in text and "nothing has moved" not in text
    assert "axis x moved between +210.250 and +370.250 mm" in text  # ρ_x's stroke
    assert "the axes stand at" in text
    assert "Likely cause: the machine's own error" in text
