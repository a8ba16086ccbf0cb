"""What the geometry in the controller buys, in whole runs of the engine (on the
Protocol-level fakes, tests/helpers/fakes.py, in front of the virtual machine): the run's
``accuracy.compensated`` against what the hidden machine does with the identified
geometry in its controller (station.record.identified reads it from the run
directory, as ``orthocal export --kinematics`` and ``orthocal compensate`` do).

The held-out machine (tests/helpers/heldout.py): axes 0.15 / −0.10 / 0.12 mm apart, leaning
0.2 / 0.1 / −0.15 mrad, Δρ (0.6, −0.4, 0.9) mm, 1 µm gauges, stands by eye, legs
stated straight to 2 µm. Offsets alone leave tens of µm there (docs/model.md, "Axes
that do not meet"); the geometry in the controller about a micrometre."""

from __future__ import annotations

from typing import Any

import heldout
import numpy as np
import pytest
from heldout import truth_now

from orthocal import Geometry
from orthocal.accuracy import error_field
from orthocal.compensation import compensated_field
from station import report
from station.record.identified import identified_machine
from station.record.result import RunResult


def true_figures(result: dict[str, Any]) -> dict[str, float]:
    """Offsets only and the geometry in the controller, on the hidden machine, over
    the grid the run stated its figures on (µm)."""
    acc = result["accuracy"]
    points = np.asarray(acc["field"]["points_mm"])
    truth = truth_now(result)
    told = identified_machine(result["run_dir"]).theta_c()
    only = error_field(points, Geometry(), truth, None, acc["frame"])
    comp = compensated_field(points, Geometry(), truth, told, acc["frame"])
    return {"only_rms": 1000 * only.rms_mm, "only_max": 1000 * only.max_mm,
            "rms": 1000 * comp.rms_mm, "max": 1000 * comp.max_mm}


@pytest.fixture(scope="module")
def held_out(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    return heldout.held_out(tmp_path_factory.mktemp("held-out"))


@pytest.fixture(scope="module")
def square(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    return heldout.square(tmp_path_factory.mktemp("square"))


def test_the_geometry_in_the_controller_takes_the_tool_to_a_micrometre(held_out) -> None:
    true = true_figures(held_out)
    assert true["only_rms"] > 25.0 and true["only_max"] > 60.0  # offsets cannot fix gaps
    assert true["rms"] <= 3.0 and true["max"] <= 8.0


def test_the_prediction_says_what_the_hidden_machine_does(held_out) -> None:
    """The figure is the mean over everything the run states, the legs' form within the
    stated 2 µm included, and the hidden legs are straight: the truth lies inside the
    interval, the figure never below it by more than 20 % + 1 µm (it would promise what
    the machine does not do), and the interval is a useful size (not the 25 µm a
    normal of the legs' worst case gave whatever the machine)."""
    comp = held_out["accuracy"]["compensated"]
    true = true_figures(held_out)
    predicted = 1000 * comp["rms_mm"]
    lo, hi = (1000 * v for v in comp["rms_interval_95_mm"])
    assert lo <= true["rms"] <= hi
    assert lo <= predicted <= hi and predicted >= true["rms"] - (0.2 * true["rms"] + 1.0)
    assert hi < 8.0
    assert comp["told"] == ["drho_x", "drho_y", "drho_z", "tilt_yx", "tilt_zx", "tilt_zy",
                            "gap_xy", "gap_xz", "gap_yz"]
    assert sorted(comp["nominal"]) == ["dL_x", "dL_y", "dL_z"]
    # beside the offsets alone, which it states as accuracy.after
    assert comp["offsets_only_rms_mm"] == held_out["accuracy"]["after"]["rms_mm"]
    RunResult.model_validate(held_out)  # the section is typed and closed


def test_the_advice_names_the_route(held_out) -> None:
    decided = {q["name"]: q["decision"] for q in held_out["statement"]}
    assert decided["tool.compensated.rms"] == "gain"
    (said,) = [a["text"] for a in held_out["advice"] if a["id"] == "controller"]
    assert "orthocal export --kinematics" in said and "orthocal compensate" in said
    text = report.summary_text(held_out)
    assert " ".join(said.split()) in " ".join(text.replace("−", "-").split())  # wrapped at 160
    line = next(ln for ln in text.splitlines() if ln.startswith("  in the controller"))
    assert "clearly lower" in line


def test_on_a_square_machine_the_routes_leave_what_the_offsets_leave(square) -> None:
    true = true_figures(square)
    assert abs(true["rms"] - true["only_rms"]) <= 1.0
    # the prediction holds there too: the tilts and gaps the model test did not keep
    # are noise about nominal, counted once, and the interval reaches a machine
    # where they are exactly nominal (it missed that, above it, on every square run)
    comp = square["accuracy"]["compensated"]
    assert abs(1000 * comp["rms_mm"] - true["rms"]) <= 0.2 * true["rms"] + 1.0
    lo, hi = (1000 * v for v in comp["rms_interval_95_mm"])
    assert lo <= true["rms"] <= hi, (lo, true["rms"], hi)
    assert square["model"] == "rho"
    assert square["accuracy"]["compensated"]["told"] == ["drho_x", "drho_y", "drho_z"]
    decided = {q["name"]: q["decision"] for q in square["statement"]}
    assert decided["tool.compensated.rms"] == "no gain"
    assert not [a for a in square["advice"] if a["id"] == "controller"]
    assert "not clearly lower" in report.summary_text(square)
