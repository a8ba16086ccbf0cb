"""``orthocal compare``'s words (station.history.compare): a run is not compared with
itself, each change says whether it is significant and by which criterion, and each
line names its one unit: lengths in µm to 0.1 µm whatever their size, tilts in mrad."""

from __future__ import annotations

import re
from typing import Any

import pytest

from station.history.compare import (
    CRITERION,
    Incomparable,
    change_lines,
    compare,
    microns,
    tilt_text,
)


def _entry(run_dir: str, x_mm: float, tilt: float, gap_mm: float) -> dict[str, Any]:
    frame = {"joint_error_mm": {a: {"value_mm": v, "std_error_mm": 0.0005}
                                for a, v in zip("xyz", (x_mm, -0.3, 0.2), strict=True)},
             "dof": 30.0}
    return {"run_dir": run_dir, "machine_id": "OG-1", "started": "2026-01-01T10:00:00+00:00",
            "geometry": {"leg_length": 310.25}, "profile": "orthocal-generic",
            "as_found": frame, "as_left": frame,
            "layout": {"tilt_yx": {"value": tilt, "std_error": 0.004},
                       "gap_xy": {"value": gap_mm, "std_error": 0.0006}}}


def test_a_run_compared_with_itself_is_refused() -> None:
    a = _entry("/runs/a", 0.4, 0.1, 0.005)
    with pytest.raises(Incomparable, match=r"same run \(/runs/a\)"):
        compare(a, a)
    # a copy of the run directory states the same run_dir: the same run
    with pytest.raises(Incomparable, match="same run"):
        compare(a, {**a})


@pytest.mark.parametrize(("value", "text"), [
    (0.0004, "+0.4"), (-0.0123456, "-12.3"), (0.0, "+0.0"),
    (-0.9994, "-999.4"), (-1.8186, "-1818.6"), (12.5, "+12500.0"), (None, "—")])
def test_lengths_in_um_to_a_tenth_whatever_their_size(value, text: str) -> None:
    assert microns(value) == text


@pytest.mark.parametrize(("value", "text"), [
    (0.152, "+0.152"), (-0.00521, "-0.00521"), (1.5, "+1.50"),
    (12.34, "+12.3"), (0.0, "+0.000"), (None, "—")])
def test_tilts_in_mrad_to_three_significant_digits(value, text: str) -> None:
    assert tilt_text(value) == text


def test_each_change_says_whether_it_is_significant() -> None:
    a = _entry("/runs/a", 0.4000, 0.100, 0.0050)
    b = _entry("/runs/b", 0.4200, 0.1005, 0.00505)  # x moved 20 µm; the rest is noise
    lines = change_lines(compare(a, b))
    by_name = {line.split("  ")[0].strip(): line for line in lines}
    assert by_name["joint x e (µm)"].endswith("  significant")
    assert by_name["joint y e (µm)"].endswith("not significant")
    assert by_name["tilt_yx (mrad)"].endswith("not significant")
    assert "+400.0 →" in by_name["joint x e (µm)"] and "+20.0" in by_name["joint x e (µm)"]
    assert "+0.100 →" in by_name["tilt_yx (mrad)"] and "+0.000500" in by_name["tilt_yx (mrad)"]
    assert "+5.0" in by_name["gap_xy (µm)"]


def test_a_column_holds_one_unit_a_joint_beyond_a_millimetre_too() -> None:
    # a calibrated machine's e is about −o: −1.5 mm, said in µm as the history lists it,
    # not "-1.5019 mm" in a column whose other lines are in µm
    a = _entry("/runs/a", -1.5019, 0.100, 0.0050)
    b = _entry("/runs/b", -1.4990, 0.1005, 0.00505)
    lines = change_lines(compare(a, b))
    joint = next(line for line in lines if line.startswith("joint x e (µm)"))
    assert "-1501.9 → -1499.0" in joint and re.search(r"change +\+2\.9 ± 1\.4 ", joint)
    for line in lines:  # the unit in the line's name, none among its numbers
        name, _, numbers = line.partition(")")
        assert name.endswith(("(µm", "(mrad")), line
        assert not re.search(r"\d\s*(mm|µm|mrad)\b", numbers), line
        assert not re.search(r"\d\.\d\d+ µm", line), line  # no µm to a thousandth
    assert "95 % interval" in CRITERION and "excludes zero" in CRITERION
