"""The picture of a joint's own test set-up: one SVG per joint tested,
``joint-test-x.svg``, drawn by hand in the mounting pictures' style
(station.report.mounting_picture) from the checked plan
(station.plan.joint_test_plan.JointTestPlan): the carriage on its rail seen from the
side, ρ growing to the right, the gauge clamped to it with its plunger along the axis
onto the reference's datum face, the reference on the base with the faces the test
sets at the plunger (to scale along the rail), the joint's way at each target, and the
gauge's stroke with the preload window the check allows. Elements carry ``data-``
attributes (the part, the face) so that a test can find what is drawn where."""

from __future__ import annotations

from pathlib import Path
from xml.sax.saxutils import escape

from drivers.files import write_atomic
from station.config import StationConfig
from station.plan.joint_test_plan import JointTestPlan, StationTest
from station.report.mounting_picture import (
    BAND,
    FONT,
    GAUGE,
    GAUGE_EDGE,
    INK,
    MOVE,
    MUTED,
    PLANE,
    WINDOW,
    arrow,
    line,
    rect,
    text,
)

WIDTH, HEIGHT = 960, 470
# The rail from X0 to X1 (ρ grows to the right), the carriage and gauge above it, the
# reference below the plunger's line.
X0, X1, RAIL_Y, LINE_Y = 80.0, 880.0, 250.0, 190.0


def file_name(axis: str) -> str:
    """The picture's file in the run directory."""
    return f"joint-test-{axis}.svg"


def _x(test: JointTestPlan, rho: float) -> float:
    lo, hi = min(test.targets), max(test.targets)
    pad = 0.08 * (hi - lo)
    return X0 + (X1 - X0) * (rho - (lo - pad)) / ((hi + pad) - (lo - pad))


def _rail(test: JointTestPlan) -> str:
    a = test.axis
    lo, hi = min(test.targets), max(test.targets)
    return "".join([
        rect(X0 - 20, RAIL_Y, X1 - X0 + 40, 14, "#e3e7ec", MUTED, 1, data={"part": "rail"}),
        text(X0 - 20, RAIL_Y + 34, f"carriage {a}'s rail (the base), ρ_{a} grows to the right",
             12, fill=MUTED),
        arrow(X1 - 60, RAIL_Y + 48, X1 + 20, RAIL_Y + 48, MUTED, 1.5),
        text(X1 + 24, RAIL_Y + 53, f"+ρ_{a}", 13, fill=MUTED),
        text(_x(test, lo), RAIL_Y + 72, f"{lo:.3f}", 12, anchor="middle", fill=MUTED),
        text(_x(test, hi), RAIL_Y + 72, f"{hi:.3f} mm", 12, anchor="middle", fill=MUTED)])


def _carriage_and_gauge(test: JointTestPlan) -> str:
    """The carriage at the datum with the gauge clamped to it, its plunger toward the
    reference's datum face."""
    s = test.sign
    xc = _x(test, test.targets[0]) - s * 70.0  # the carriage's centre, behind the gauge
    tip = _x(test, test.targets[0])  # the plunger's tip on the datum face
    body = xc + s * 10.0
    out = [rect(xc - 38, RAIL_Y - 44, 76, 44, "#dfe6ee", INK, data={"part": "carriage"}),
           text(xc, RAIL_Y - 52, f"carriage {test.axis}", 13, anchor="middle"),
           rect(min(body, body + s * 40), LINE_Y - 14, 40, 28, GAUGE, GAUGE_EDGE, 2,
                data={"gauge": test.gauge, "part": "body"}),
           line(xc, RAIL_Y - 44, xc, LINE_Y + 14, MUTED, 4),
           line(body + s * 40, LINE_Y, tip, LINE_Y, INK, 3.5,
                data={"gauge": test.gauge, "part": "plunger"}),
           text(body + s * 20, LINE_Y - 22, test.gauge, 17, anchor="middle", weight="bold",
                data={"gauge": test.gauge, "part": "name"})]
    return "".join(out)


def _reference(test: JointTestPlan) -> str:
    """The datum face at the plunger's tip, and each face the test sets there: the
    joint stands where face k meets the plunger as the datum did (model.md (J9))."""
    out = [text(X0 - 20, 100, f"the {test.reference}: its faces from the datum", 14,
                weight="bold", fill=PLANE)]
    x_datum = _x(test, test.targets[0])
    out.append(rect(x_datum - (0 if test.sign < 0 else 8) - (8 if test.sign < 0 else 0),
                    LINE_Y - 30, 8, 60, BAND, PLANE, 2, data={"part": "datum face"}))
    for k, (rho, face) in enumerate(zip(test.targets, test.faces, strict=True)):
        x = _x(test, rho)
        out.append(line(x, LINE_Y + 20, x, RAIL_Y - 4, PLANE, 1.5, dash="4 3",
                        data={"part": "target", "face": f"{face:.3f}"}))
        out.append(text(x, 124 + 16 * (k % 2), f"{face:.1f}", 11, anchor="middle",
                        fill=PLANE))
    out.append(text(X0 - 20, 160, "mm: the carriage goes where each face, set in turn at the "
                                  "plunger, meets it as the datum did", 11, fill=MUTED))
    return "".join(out)


def _window(test: JointTestPlan, stroke: float, preload: float) -> str:
    x0, x1, y = 520.0, 900.0, 380.0
    k = (x1 - x0) / stroke
    out = [rect(x0, y + 6, x1 - x0, 14, "#ffffff", INK, 1)]
    if test.window is not None:
        lo, hi = test.window
        out.append(rect(x0 + max(lo, 0.0) * k, y + 6, max(hi - lo, 0.0) * k, 14, WINDOW,
                        MOVE, 1.5, data={"part": "window", "window": f"{lo:.2f}-{hi:.2f}"}))
        words = f"push in {lo:.2f}–{hi:.2f} mm at the datum"
    else:
        words = f"push in {preload:.2f} mm (the plan is not checked)"
    xq = x0 + preload * k
    out += [line(xq, y + 2, xq, y + 24, INK, 2.5),
            text(x0, y - 4, f"{test.gauge}: {words}", 14, weight="bold",
                 data={"part": "window-label"}),
            text(x0, y + 40, f"of its {stroke:g} mm stroke; the black mark: the config's "
                             f"preload, {preload:.2f} mm", 12, fill=MUTED)]
    return "".join(out)


def draw(test: JointTestPlan, stroke_mm: float, preload_mm: float) -> str:
    """The picture of joint ``test.axis``'s test set-up, a standalone SVG document."""
    toward = "lower" if test.sign < 0 else "higher"
    title = (f"Joint {test.axis}'s own test: gauge {test.gauge} on carriage {test.axis}, "
             f"the {test.reference} on the base")
    words = [f"Only joint {test.axis} moves, the others at Π0; every other gauge off.",
             f"The plunger along the axis, pointing toward {toward} ρ, onto the datum face "
             f"at ρ_{test.axis} = {test.targets[0]:.3f} mm.",
             f"At each target the operator sets the next face at the plunger; each is "
             f"approached {test.repeats} times from each side."]
    body = [rect(0, 0, WIDTH, HEIGHT, "#ffffff"), text(20, 30, title, 20, weight="bold"),
            *(text(20, 52 + 16 * n, w, 13, fill=MUTED) for n, w in enumerate(words)),
            _reference(test), _rail(test), _carriage_and_gauge(test),
            _window(test, stroke_mm, preload_mm),
            text(20, 396, f"{len(test.targets)} targets, then the datum again", 14,
                 weight="bold"),
            text(20, 416, "(its drift over the test is taken out)", 12, fill=MUTED)]
    return (f'<svg xmlns="http://www.w3.org/2000/svg" width="{WIDTH}" height="{HEIGHT}" '
            f'viewBox="0 0 {WIDTH} {HEIGHT}" font-family="{FONT}" role="img" '
            f'data-joint="{test.axis}">'
            f"<title>{escape(title)}</title>{''.join(body)}</svg>\n")


def write_joint_pictures(directory: Path, test: StationTest, config: StationConfig, *,
                         missing_only: bool = False) -> list[Path]:
    """Each tested joint's picture into ``directory`` (:func:`file_name`), atomically;
    with ``missing_only`` those already there are left as they are (a resumed run's
    operator saw them). OSError is the caller's to word."""
    paths = []
    for jp in test.joints:
        path = Path(directory) / file_name(jp.axis)
        if not (missing_only and path.exists()):
            ind = config.indicator(jp.gauge)
            write_atomic(path, draw(jp, ind.stroke_mm, ind.preload))
        paths.append(path)
    return paths
