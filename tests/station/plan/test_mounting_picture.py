"""Each setup's mounting picture (station.report.mounting_picture) and the prompt's
words (station.console.operator.mount_instruction) from one sheet
(station.plan.mounting): well-formed SVG naming every gauge, each plunger on the
side, face and window the plan and the simulator say, a reversed mount drawn on the
other side (docs/design.md, "Mounting pictures")."""

from __future__ import annotations

import dataclasses
import xml.etree.ElementTree as ET

import pytest
from builders import station_config
from fakes import FakeRig

import orthocal
from station.console.operator import mount_instruction
from station.plan.check import check_plan
from station.plan.mounting import (
    MountingSheet,
    cross_axes,
    sheet_of,
    sheets_of,
    travel_key,
    window,
)
from station.plan.steps import Plan, build_plan
from station.report.mounting_picture import CX, CY, draw

SVG = "{http://www.w3.org/2000/svg}"
WIDE = ([-1e9] * 3, [1e9] * 3)


@pytest.fixture(scope="module")
def checked() -> tuple[object, Plan]:
    """The tests' station (builders.BASE: gauge B reversed on leg y), its plan checked."""
    config = station_config()
    plan = build_plan(config)
    check_plan(plan, config, WIDE)
    return config, plan


def _parse(svg: str) -> ET.Element:
    return ET.fromstring(svg)  # raises on anything not well-formed


def _parts(root: ET.Element, tag: str, **data: str) -> list[ET.Element]:
    return [e for e in root.iter(SVG + tag)
            if all(e.get(f"data-{k}") == v for k, v in data.items())]


def _centre(rect: ET.Element) -> tuple[float, float]:
    return (float(rect.get("x", 0)) + float(rect.get("width", 0)) / 2,
            float(rect.get("y", 0)) + float(rect.get("height", 0)) / 2)


def test_each_picture_is_an_svg_naming_its_leg_and_every_gauge(checked) -> None:
    config, plan = checked
    sheets = sheets_of(config, plan)
    assert [s.file_name for s in sheets] == ["mounting-1-leg-x.svg", "mounting-2-leg-y.svg",
                                             "mounting-3-leg-z.svg"]
    for sheet in sheets:
        root = _parse(draw(sheet))
        assert root.tag == SVG + "svg" and root.get("data-leg") == sheet.leg
        title = root.find(SVG + "title")
        assert title is not None and f"leg {sheet.leg}" in (title.text or "")
        texts = " ".join(t.text or "" for t in root.iter(SVG + "text"))
        for g in sheet.gauges:
            named = [t.text for t in _parts(root, "text", gauge=g.name, part="name")]
            assert named == [g.name]
            assert f"{g.name}: along {g.face}" in texts
        # the stand: the plane, its band of ± stand_tolerance_mm along the leg, at L/2
        assert "155.1 mm (L/2)" in texts and "within ±5 mm" in texts
        band = _parts(root, "rect", part="tolerance")[0]
        plane = _parts(root, "line", part="plane")[0]
        scale = 360.0 / config.machine.leg_length  # the side view's px per mm
        assert float(band.get("width", 0)) == pytest.approx(
            2 * config.procedure.stand_tolerance_mm * scale, abs=0.1)
        assert _centre(band)[0] == pytest.approx(float(plane.get("x1", 0)), abs=0.1)


def test_the_windows_are_the_plan_checks(checked) -> None:
    config, plan = checked
    margin = config.procedure.plunger_margin_mm
    for sp in plan.setups:
        sheet = sheet_of(config, plan, sp)
        root = _parse(draw(sheet))
        texts = " ".join(t.text or "" for t in root.iter(SVG + "text"))
        for g in sheet.gauges:
            stroke = config.indicator(g.name).stroke_mm
            lo, hi = window(stroke, margin, plan.travel[travel_key(g.name, sp)])
            assert g.window_mm == (lo, hi)
            assert margin < lo < hi < stroke - margin  # a window, inside the stroke
            assert f"{g.name}: push in {lo:.2f}–{hi:.2f} mm" in texts
            shaded = _parts(root, "rect", gauge=g.name, part="window")[0]
            assert shaded.get("data-window") == f"{lo:.2f}-{hi:.2f}"
            # drawn to scale on the stroke's bar (560 .. 900 px: 0 .. stroke)
            k = 340.0 / stroke
            assert (float(shaded.get("x", 0)) - 560.0) / k == pytest.approx(lo, abs=0.01)
            assert float(shaded.get("width", 0)) / k == pytest.approx(hi - lo, abs=0.01)


def _body_offset(root: ET.Element, name: str) -> tuple[float, float]:
    """Where gauge ``name``'s body sits in the section, from the touched bar's centre,
    as (along the first cross axis, along the second): right and up on the page."""
    bar = _parts(root, "circle", part="touched bar")[0]
    assert (float(bar.get("cx", 0)), float(bar.get("cy", 0))) == (CX, CY)
    x, y = _centre(_parts(root, "rect", gauge=name, part="body")[0])
    return x - CX, CY - y


def test_each_gauge_stands_on_the_side_its_direction_says(checked) -> None:
    config, plan = checked
    for sheet in sheets_of(config, plan):
        root = _parse(draw(sheet))
        a, _ = cross_axes(sheet.leg)
        for g in sheet.gauges:
            along_a, along_b = _body_offset(root, g.name)
            toward = along_a if g.axis == a else along_b
            across = along_b if g.axis == a else along_a
            assert toward * g.sign > 60 and abs(across) < 1e-6, (sheet.leg, g)
            group = _parts(root, "g", gauge=g.name)[0]
            assert group.get("data-direction") == g.direction
            assert group.get("data-face") == g.face


def test_a_reversed_mount_is_drawn_reversed(checked) -> None:
    config, plan = checked
    sheet = sheet_of(config, plan, plan.setups[1])  # leg y: A along x, B along −z
    b_gauge = next(g for g in sheet.gauges if g.name == "B")
    assert b_gauge.direction == "-z" and b_gauge.reversed
    assert (b_gauge.face, b_gauge.pointing) == ("\u2212z", "+z")
    forward = dataclasses.replace(sheet, gauges=tuple(
        dataclasses.replace(g, direction="z") if g.name == "B" else g for g in sheet.gauges))
    rev_root, fwd_root = _parse(draw(sheet)), _parse(draw(forward))
    # leg y's section: z to the right, x up; reversed, B stands left of the bar
    assert cross_axes("y") == ("z", "x")
    assert _body_offset(rev_root, "B")[0] < -60 < 60 < _body_offset(fwd_root, "B")[0]
    # its positive reading: the leg moving −z (left on the page), +z when not reversed
    for root, way in ((rev_root, -1), (fwd_root, +1)):
        arrow = _parts(root, "line", gauge="B", part="positive")[0]
        dx = float(arrow.get("x2", 0)) - float(arrow.get("x1", 0))
        assert dx * way > 20
    rev_text = " ".join(t.text or "" for t in rev_root.iter(SVG + "text"))
    assert "B: along \u2212z (a reversed mount)" in rev_text
    assert "reads + as the leg moves \u2212z" in rev_text
    # A is drawn where it was: only B turned round
    assert _body_offset(rev_root, "A") == pytest.approx(_body_offset(fwd_root, "A"))


def test_the_sign_is_the_simulators(checked) -> None:
    # the words "reads + as the leg moves <face>" against the simulated machine: at Π0,
    # mounted, then the end point moved 2 mm along the gauge's axis, which moves leg
    # i's crossing of the plane by f·2 mm the same way (docs/model.md, "Measurement")
    config, plan = checked
    rig = FakeRig()
    geometry = rig.geometry
    for sheet in sheets_of(config, plan):
        for g in sheet.gauges:
            rig.axes.move_and_wait(orthocal.posture("0", None, geometry))
            rig.mount(g.name, sheet.leg, g.direction, at=sheet.at)
            rig.axes.move_and_wait(orthocal.posture("+2", g.axis, geometry))
            reading = rig.gauges[g.name].read()
            assert reading == pytest.approx(g.sign * sheet.at * 2.0, abs=0.01), (sheet.leg, g)
            rig.unmount(g.name)


def test_the_prompt_says_what_the_picture_draws(checked) -> None:
    config, plan = checked
    sheet = sheet_of(config, plan, plan.setups[1])
    text = mount_instruction("m", 1, "y", plan.setups[1].indicators, ["A", "B", "C"],
                             sheet=sheet, picture="runs/run-1/mounting-2-leg-y.svg")
    lines = text.split("\n")
    assert lines[0] == ("measurement, setup 2: the machine is at Π0. Mount A, B against "
                        "the middle of leg y; remove C.")
    assert lines[1].strip() == "picture: runs/run-1/mounting-2-leg-y.svg"
    assert "155.1 mm (L/2) from the centre of the carriage's joint" in text
    assert "within ±5 mm" in text
    assert "on the parallelogram's bar on their side" in text
    a, b = (next(g for g in sheet.gauges if g.name == n) for n in "AB")
    assert a.window_mm is not None and b.window_mm is not None
    assert (f"A along +x: on the +x side, plunger onto the +x face; reads + as the "
            f"leg moves +x; push in {a.window_mm[0]:.2f}–{a.window_mm[1]:.2f} mm") in lines[4]
    assert (f"B along −z (reversed): on the −z side, plunger onto the −z face; "
            f"reads + as the leg moves −z; push in {b.window_mm[0]:.2f}–"
            f"{b.window_mm[1]:.2f} mm") in lines[5]
    assert len(lines) == 6 and max(len(line) for line in lines) < 120  # a few short lines


def test_an_unchecked_plan_and_a_second_plane_say_so(checked) -> None:
    config, _ = checked
    plan = build_plan(config)  # not checked: no travel, no window
    sheet = dataclasses.replace(sheet_of(config, plan, plan.setups[0]), at=0.75,
                                tolerance_mm=0.0)
    assert all(g.window_mm is None for g in sheet.gauges)
    root = _parse(draw(sheet))
    texts = " ".join(t.text or "" for t in root.iter(SVG + "text"))
    assert "232.7 mm (0.75·L)" in texts and "77.6 mm" in texts
    assert "stand exactly here (tolerance 0)" in texts
    assert "the plan is not checked" in texts and not _parts(root, "rect", part="window")
    text = mount_instruction("m", 0, "x", plan.setups[0].indicators, ["A", "B"], 0.75,
                             sheet=sheet)
    assert "232.7 mm (0.75·L)" in text and "placed exactly" in text
    assert "push in 6.25 mm" in text


def test_a_one_gauge_setup_is_drawn(checked) -> None:
    config, plan = checked
    full = sheet_of(config, plan, plan.setups[0])
    one: MountingSheet = dataclasses.replace(full, gauges=full.gauges[:1])
    root = _parse(draw(one))
    assert len(_parts(root, "g", part="gauge")) == 1
    assert _parts(root, "text", gauge="A", part="name")
    assert not _parts(root, "text", gauge="B")
