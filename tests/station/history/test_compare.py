"""``orthocal compare``'s numbers and words (station.history.compare, orthocal.between_runs):
a run is not compared with itself; where both runs state the machine, each change's
uncertainty combines the two runs' by the GUM, the legs' straightness common to both
cancelling but for the difference of its parts, the scatter and every other input
independent; each line prints its values as every view prints a quantity
(station.record.quantity_text) and says whether the change is significant, and by which
criterion. An entry from before the statement keeps its standard error alone."""

from __future__ import annotations

import math
from typing import Any

import pytest

from orthocal import coverage_factor
from orthocal.between_runs import Stated, change, of_statement
from station.history.compare import (
    COMMON,
    CRITERION,
    Incomparable,
    change_lines,
    compare,
    microns,
)

#: A run's statement of one joint as its history entry keeps it: the scatter, the legs'
#: straightness (common to every run of the machine), one gauge's MPE (its own mounting).
PARTS = {"repeatability": 0.0004, "leg straightness": 0.0010, "gauge MPE A (leg x, along y)":
         0.0003}


def _stated(value: float, parts: dict[str, float] = PARTS, dof: float = 200.0
            ) -> dict[str, Any]:
    """An entry's value as the statement gave it: U = k·u_c on its Welch–Satterthwaite
    dof (Type A on ``dof_a``, Type B at ∞)."""
    u_c = math.sqrt(sum(u * u for u in parts.values()))
    dof_eff = dof * u_c ** 4 / parts["repeatability"] ** 4
    k = coverage_factor(dof_eff)
    return {"value_mm": value, "std_error_mm": parts["repeatability"],
            "expanded_95_mm": k * u_c, "k": k, "dof": dof_eff,
            "contributions_mm": dict(parts), "stated": True}


def _entry(run_dir: str, x_mm: float, tilt: float, gap_mm: float,
           stated: bool = False) -> dict[str, Any]:
    values = (x_mm, -0.3, 0.2)
    if stated:
        joints = {a: _stated(v) for a, v in zip("xyz", values, strict=True)}
    else:
        joints = {a: {"value_mm": v, "std_error_mm": 0.0005}
                  for a, v in zip("xyz", values, strict=True)}
    frame = {"joint_error_mm": joints, "dof": None if stated else 30.0}
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
def test_history_s_columns_say_lengths_in_um_to_a_tenth(value, text: str) -> None:
    assert microns(value) == text


def test_a_common_input_cancels_in_the_change_and_the_others_add() -> None:
    a = Stated(0.0, 0.0004, 50.0, {"leg straightness": 0.0010, "temperature": 0.0002})
    b = Stated(0.0020, 0.0003, 80.0, {"leg straightness": 0.0012, "temperature": 0.0002})
    c = change(a, b, COMMON)
    # (C1): the scatter and the temperature independent, the straightness by its
    # difference alone
    u2 = 0.0004 ** 2 + 0.0003 ** 2 + 2 * 0.0002 ** 2 + (0.0012 - 0.0010) ** 2
    assert c.u_c == pytest.approx(math.sqrt(u2), rel=1e-12)
    assert c.value == pytest.approx(0.0020)
    # Welch–Satterthwaite over the two scatters, the Type B at ∞ dof
    assert c.dof == pytest.approx(u2 ** 2 / (0.0004 ** 4 / 50.0 + 0.0003 ** 4 / 80.0))
    assert c.expanded == pytest.approx(coverage_factor(c.dof) * c.u_c)
    assert c.significant  # 2 µm against U ≈ 1.2 µm
    # the same inputs taken independent: larger, as a straight sum of the two runs'
    apart = change(a, b, ())
    assert apart.u_c == pytest.approx(math.sqrt(u2 - 0.0002 ** 2 + 0.0010 ** 2 + 0.0012 ** 2))
    assert apart.u_c > c.u_c
    # a bound a run added whole (tilts or bows) is added whole again
    whole = change(Stated(0.0, 0.0004, 50.0, {}, whole=0.003), b, COMMON)
    assert whole.expanded == pytest.approx(
        coverage_factor(whole.dof) * whole.u_c + 0.003)


def test_a_statement_s_parts_are_read_back_from_its_u_k_and_dof() -> None:
    said = _stated(0.4, dof=59.0)
    s = of_statement(0.4, said["expanded_95_mm"], said["k"], said["dof"],
                     said["contributions_mm"])
    assert s.u_a == pytest.approx(0.0004) and s.dof_a == pytest.approx(59.0)
    assert s.type_b == {k: v for k, v in PARTS.items() if k != "repeatability"}
    assert s.whole == pytest.approx(0.0, abs=1e-12)
    added = of_statement(0.4, said["expanded_95_mm"] + 0.0015, said["k"], said["dof"],
                         said["contributions_mm"])
    assert added.whole == pytest.approx(0.0015)


def test_compare_combines_the_statements_and_prints_them_as_every_view() -> None:
    a = _entry("/runs/a", -1.5019, 0.100, 0.0050, stated=True)
    b = _entry("/runs/b", -1.4990, 0.1005, 0.00505, stated=True)
    doc = compare(a, b)
    x = doc["joint_error_mm"]["x"]
    # the legs' straightness cancels: u² = 2·u_A² + 2·u_MPE², not 2·u_c²
    u = math.sqrt(2 * 0.0004 ** 2 + 2 * 0.0003 ** 2)
    assert x["std_error"] == pytest.approx(u, rel=1e-9)
    assert x["interval_95"] == pytest.approx(x["k"] * u, rel=1e-9)
    assert x["before_expanded"] == pytest.approx(a["as_left"]["joint_error_mm"]["x"][
        "expanded_95_mm"])
    assert x["significant"] is True  # 2.9 µm against U ≈ 1.4 µm
    lines = change_lines(doc)
    joint = next(line for line in lines if line.startswith("joint x e"))
    # quantity_text's rules: above 0.1 mm in mm with the ± in µm; the change in µm
    said = a["as_left"]["joint_error_mm"]["x"]["expanded_95_mm"]
    assert f"-1.502 mm ± {1000 * said:.1f} µm → -1.499 mm ± {1000 * said:.1f} µm" in joint
    assert f"change +2.9 ± {1000 * x['interval_95']:.1f} µm (95 %)" in joint
    assert joint.endswith("  significant")


def test_a_legacy_entry_keeps_its_standard_error_alone() -> None:
    a = _entry("/runs/a", 0.4000, 0.100, 0.0050)
    b = _entry("/runs/b", 0.4200, 0.1005, 0.00505)  # x moved 20 µm; the rest is noise
    doc = compare(a, b)
    x = doc["joint_error_mm"]["x"]
    k = coverage_factor(30.0)
    assert x["interval_95"] == pytest.approx(k * math.hypot(0.0005, 0.0005))
    assert x["before_expanded"] is None  # the run stated no U
    by_name = {line.split("  ")[0].strip(): line for line in change_lines(doc)}
    assert by_name["joint x e"].endswith("  significant")
    assert by_name["joint y e"].endswith("not significant")
    assert by_name["tilt_yx"].endswith("not significant")
    assert "+0.400 mm →" in by_name["joint x e"] and "change +20.0 ± 1.4 µm" in \
        by_name["joint x e"]
    assert "+0.100 mrad → +0.101 mrad" in by_name["tilt_yx"]
    assert "change +0.0 ± 1.7 µm" in by_name["gap_xy"] and "+5.0 µm →     +5.0 µm" in \
        by_name["gap_xy"]
    assert "lies beyond its 95 % expanded uncertainty" in CRITERION
