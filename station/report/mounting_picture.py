"""The picture of a mounting: one SVG per setup, drawn by hand from its
:class:`~station.plan.mounting.MountingSheet` (a pure function of the setup and the
plan's numbers; station.report.mounting_files writes it into the run directory).

Three parts. The leg from the side: its end point's and its carriage's joints, the
carriage on the axis it rides on, the parallelogram's two bars (the one the plungers
touch drawn solid), the gauge plane at ``at``·L from the carriage's joint with the
stand's tolerance band, the distances from both joints. The section in the gauge
plane, seen from the carriage: the two bars, each gauge on its side with its plunger
onto the face it touches, and the way the leg moves for a positive reading. Per
gauge: its direction, face and sign in words, and its plunger's stroke with the
preload window the plan check allows. The conventions are station.plan.mounting's.

Elements carry ``data-`` attributes (the gauge, its direction, the part) so that a
test can find what is drawn where; no ``id``, so that several pictures inline in
one report.html do not collide.
"""

from __future__ import annotations

from xml.sax.saxutils import escape, quoteattr

from station.plan.mounting import GaugeMount, MountingSheet, cross_axes, signed

WIDTH = 960
INK, MUTED, PLANE, BAND = "#1d2330", "#6b7480", "#c0392b", "#f8d7da"
BAR, OTHER, GAUGE, GAUGE_EDGE = "#1f4e79", "#9aa5b1", "#fff3cd", "#8a6d00"
MOVE, WINDOW, FACE = "#1e7b34", "#cfe9d6", "#e67e22"
FONT = "DejaVu Sans, Arial, Helvetica, sans-serif"

# The side view: the end point's joint at X0, the carriage's at X1, on the line YC.
X0, X1, YC, HALF_SPACING = 110.0, 470.0, 262.0, 18.0
# The section: the touched bar's centre, its radius, the plunger's length, the body's.
CX, CY, R_BAR, PLUNGER, BODY = 760.0, 262.0, 18.0, 40.0, 52.0
# Where the gauges' rows start, and each row's height.
ROWS, ROW = 500.0, 76.0


def _num(v: float) -> str:
    """A length to 0.1 mm, as a stand is set (and no trailing ".0")."""
    return f"{v:.1f}".removesuffix(".0")


def _attrs(extra: dict[str, str] | None) -> str:
    return "".join(f" data-{k}={quoteattr(v)}" for k, v in (extra or {}).items())


def text(x: float, y: float, s: str, size: float = 14, *, weight: str = "normal",
         anchor: str = "start", fill: str = INK, data: dict[str, str] | None = None) -> str:
    return (f'<text x="{x:.1f}" y="{y:.1f}" font-size="{size:g}" font-weight="{weight}" '
            f'text-anchor="{anchor}" fill="{fill}"{_attrs(data)}>{escape(s)}</text>')


def line(x1: float, y1: float, x2: float, y2: float, color: str = INK, width: float = 1.5,
         dash: str | None = None, data: dict[str, str] | None = None) -> str:
    d = f' stroke-dasharray="{dash}"' if dash else ""
    return (f'<line x1="{x1:.1f}" y1="{y1:.1f}" x2="{x2:.1f}" y2="{y2:.1f}" '
            f'stroke="{color}" stroke-width="{width:g}"{d}{_attrs(data)}/>')


def rect(x: float, y: float, w: float, h: float, fill: str, edge: str = "none",
         width: float = 1.5, data: dict[str, str] | None = None) -> str:
    return (f'<rect x="{x:.1f}" y="{y:.1f}" width="{w:.1f}" height="{h:.1f}" fill="{fill}" '
            f'stroke="{edge}" stroke-width="{width:g}"{_attrs(data)}/>')


def circle(x: float, y: float, r: float, fill: str, edge: str = "none", width: float = 1.5,
           dash: str | None = None, data: dict[str, str] | None = None) -> str:
    d = f' stroke-dasharray="{dash}"' if dash else ""
    return (f'<circle cx="{x:.1f}" cy="{y:.1f}" r="{r:g}" fill="{fill}" stroke="{edge}" '
            f'stroke-width="{width:g}"{d}{_attrs(data)}/>')


def arrow(x1: float, y1: float, x2: float, y2: float, color: str = INK, width: float = 2.0,
          both: bool = False, data: dict[str, str] | None = None) -> str:
    """A line from (x1, y1) to (x2, y2) with a filled head at the end (and the start)."""
    out = [line(x1, y1, x2, y2, color, width, data=data), _head(x1, y1, x2, y2, color)]
    if both:
        out.append(_head(x2, y2, x1, y1, color))
    return "".join(out)


def _head(x1: float, y1: float, x2: float, y2: float, color: str, size: float = 9.0) -> str:
    dx, dy = x2 - x1, y2 - y1
    n = max((dx * dx + dy * dy) ** 0.5, 1e-9)
    ux, uy = dx / n, dy / n
    bx, by = x2 - ux * size, y2 - uy * size
    pts = [(x2, y2), (bx - uy * size * 0.45, by + ux * size * 0.45),
           (bx + uy * size * 0.45, by - ux * size * 0.45)]
    return (f'<polygon points="{" ".join(f"{px:.1f},{py:.1f}" for px, py in pts)}" '
            f'fill="{color}"/>')


def axes_glyph(x: float, y: float, right: str, up: str) -> str:
    """Two short arrows naming the view's directions: ``right`` and ``up``."""
    return (arrow(x, y, x + 42, y, MUTED, 1.5) + arrow(x, y, x, y - 42, MUTED, 1.5)
            + text(x + 47, y + 5, right, 13, fill=MUTED)
            + text(x - 4, y - 48, up, 13, fill=MUTED, anchor="middle"))


# --- the leg from the side ----------------------------------------------------------


def _side_view(sheet: MountingSheet) -> str:
    """The leg from the side: the second cross axis up, the leg's axis to the right
    (from the end point to the carriage, as they stand at Π0)."""
    a, b = cross_axes(sheet.leg)
    side_b = sheet.bar_side()[b]
    scale = (X1 - X0) / sheet.leg_length_mm
    xp = X1 - sheet.from_carriage_mm * scale  # the gauge plane
    y_touch, y_other = YC - HALF_SPACING * side_b, YC + HALF_SPACING * side_b
    band = max(sheet.tolerance_mm * scale, 0.0)
    out = [text(20, 98, f"Leg {sheet.leg} from the side", 16, weight="bold"),
           text(20, 116, f"(seen from {signed(a, -1)})", 12, fill=MUTED),
           rect(xp - band, YC - 112, 2 * band, 224, BAND, data={"part": "tolerance"}),
           # the axis the carriage rides on: at Π0 the leg lies along it, P at 0
           line(30, YC, 548, YC, MUTED, 1, dash="10 4 2 4"),
           rect(X1 + 6, YC - 7, 540 - X1, 14, "#e3e7ec", OTHER, 1),
           _head(530, YC, 554, YC, MUTED, 12),
           rect(X1 + 4, YC - 32, 58, 64, "#dfe6ee", INK, data={"part": "carriage"}),
           text(X1 + 33, YC - 40, "carriage", 13, anchor="middle"),
           text(X1 + 33, YC + 50, f"on axis {sheet.leg}", 12, anchor="middle", fill=MUTED),
           rect(X0 - 56, YC - 30, 50, 60, "#dfe6ee", INK, data={"part": "end point"}),
           text(X0 - 31, YC + 48, "end point", 13, anchor="middle"),
           text(X0 - 31, YC + 64, "(the tool)", 12, anchor="middle", fill=MUTED)]
    for y, color, width, dash, part in ((y_other, OTHER, 5, "7 4", "other bar"),
                                        (y_touch, BAR, 7, None, "touched bar")):
        out.append(line(X0, y, X1, y, color, width, dash, data={"part": part}))
    for x in (X0, X1):  # the short links, with the joints' centres on the leg's line
        out.append(line(x, YC - HALF_SPACING, x, YC + HALF_SPACING, INK, 3))
        out.extend(circle(x, y, 4.5, "#ffffff", INK) for y in (y_touch, y_other))
        out.append(circle(x, YC, 3.5, INK))
    # the bars' names on the longer of the two stretches the plane leaves
    mid = (X0 + xp) / 2 if xp - X0 > X1 - xp else (xp + X1) / 2
    above, below = -12.0, 24.0
    out.append(text(mid, y_touch + (above if side_b > 0 else below),
                    "bar the plungers touch", 13, anchor="middle", fill=BAR, weight="bold"))
    out.append(text(mid, y_other + (below if side_b > 0 else above), "other bar", 13,
                    anchor="middle", fill=MUTED))
    out.append(line(xp, YC - 112, xp, YC + 112, PLANE, 2, dash="6 4", data={"part": "plane"}))
    out.extend(_dimensions(sheet, xp))
    out.append(_side_gauges(sheet, xp, y_touch, side_b))
    out.append(axes_glyph(40, 196, f"+{sheet.leg}", f"+{b}"))
    return "".join(out)


def _dimensions(sheet: MountingSheet, xp: float) -> list[str]:
    """The plane's distances from the carriage's joint (above) and the end point's
    (below), and the stand's tolerance."""
    frac = "L/2" if sheet.middle else f"{sheet.at:g}·L"
    top, low = YC - 96, YC + 96
    return [line(X1, YC - 8, X1, top - 8, MUTED, 1), line(X0, YC + 8, X0, low + 8, MUTED, 1),
            arrow(X1, top, xp, top, PLANE, 1.5, both=True),
            text((X1 + xp) / 2, top - 8, f"{_num(sheet.from_carriage_mm)} mm ({frac})", 14,
                 anchor="middle", weight="bold", fill=PLANE, data={"part": "from-carriage"}),
            text(X1 - 4, top + 16, "from the carriage's joint", 12, anchor="end", fill=PLANE),
            arrow(X0, low, xp, low, PLANE, 1.5, both=True),
            text((X0 + xp) / 2, low - 6, f"{_num(sheet.from_end_mm)} mm", 13,
                 anchor="middle", fill=PLANE),
            text((X0 + xp) / 2, low + 16, "from the end point's joint", 12, anchor="middle",
                 fill=PLANE),
            text(xp, YC - 120, "gauge plane", 13, anchor="middle", fill=PLANE, weight="bold"),
            text(xp, YC + 134, "stand exactly here (tolerance 0)" if sheet.tolerance_mm <= 0
                 else f"stand here, {sheet.tolerance_words()}", 13, anchor="middle",
                 fill=PLANE, weight="bold", data={"part": "tolerance-label"}),
            text(20, YC + 160, f"L = {sheet.leg_length_mm:g} mm, joint to joint; "
                               "distances along the leg at Π0", 12, fill=MUTED)]


def _side_gauges(sheet: MountingSheet, xp: float, y_touch: float, side_b: int) -> str:
    """The gauges in the side view: the one along the view's vertical drawn with its
    plunger onto the bar; the one toward or away from the viewer named at the plane."""
    _, b = cross_axes(sheet.leg)
    out = []
    for g in sheet.gauges:
        if g.axis == b:
            face_y = y_touch - 3.5 * g.sign  # the bar's face on the gauge's side
            tip = face_y - 22 * g.sign
            body_y = tip - 34 * g.sign
            out.append(line(xp, face_y, xp, tip, INK, 3))
            out.append(rect(xp - 12, min(tip, body_y), 24, 34, GAUGE, GAUGE_EDGE,
                            data={"gauge": g.name, "part": "side-body"}))
            out.append(text(xp + 18, (tip + body_y) / 2 + 6, g.name, 16, weight="bold",
                            data={"gauge": g.name}))
        else:
            where = "behind the leg" if g.sign > 0 else "in front of the leg"
            y = YC + (72 if side_b > 0 else -60)
            out.append(line(xp + 2, y + (-12 if side_b > 0 else 4), xp + 12, y_touch, MUTED, 1))
            out.append(text(xp + 10, y, f"{g.name}: {where} ({g.face} side)", 13,
                            data={"gauge": g.name}))
    return "".join(out)


# --- the section in the gauge plane ----------------------------------------------------


def _screen(du_a: float, du_b: float) -> tuple[float, float]:
    """A point of the section (along the first cross axis, along the second; px of the
    drawing) on the page: the first points right, the second up."""
    return CX + du_a, CY - du_b


def _section(sheet: MountingSheet) -> str:
    """The section in the gauge plane, seen from the carriage: the touched bar at the
    centre, the other bar away from the gauges, each gauge on its side."""
    a, b = cross_axes(sheet.leg)
    sides = sheet.bar_side()
    ox, oy = _screen(-sides[a] * 44, -sides[b] * 44)
    out = [text(580, 98, "In the gauge plane", 16, weight="bold"),
           text(580, 116, f"(seen from the carriage, looking along {signed(sheet.leg, -1)})",
                12, fill=MUTED),
           circle(ox, oy, R_BAR, "#ffffff", OTHER, 2.5, dash="5 3", data={"part": "other bar"}),
           text(ox, oy + (R_BAR + 16 if sides[b] > 0 else -R_BAR - 8), "other bar", 12,
                anchor="middle", fill=MUTED),
           circle(CX, CY, R_BAR, BAR, data={"part": "touched bar"})]
    out.extend(_section_gauge(g, a, sides[a] if g.axis == b else sides[b])
               for g in sheet.gauges)
    out.append(axes_glyph(600, 420, f"+{a}", f"+{b}"))
    out.append(arrow(700, 416, 728, 416, MOVE, 2.5))
    out.append(text(734, 421, "the leg's way that reads +", 12, fill=MOVE))
    return "".join(out)


def _section_gauge(g: GaugeMount, a: str, other: int) -> str:
    """One gauge in the section: its stand, its body on its side, its plunger onto the
    face it touches (marked), and the leg's way for a positive reading, on the side
    of the plunger away from the other gauge (``other``: that gauge's side, +1/−1)."""
    across = g.axis == a  # drawn left or right of the bar, else above or below
    ua, ub = (g.sign, 0) if across else (0, g.sign)  # toward the gauge
    fx, fy = _screen(ua * R_BAR, ub * R_BAR)  # the face touched
    tx, ty = _screen(ua * (R_BAR + PLUNGER), ub * (R_BAR + PLUNGER))  # the plunger's end
    ex, ey = _screen(ua * (R_BAR + PLUNGER + BODY), ub * (R_BAR + PLUNGER + BODY))
    group = {"gauge": g.name, "direction": g.direction, "face": g.face, "part": "gauge"}
    out = [f"<g{_attrs(group)}>",
           _stand(tx, ty, ex, ey, across)]
    w, h = (abs(ex - tx), 30.0) if across else (30.0, abs(ey - ty))
    out.append(rect(min(tx, ex) - (0 if across else 15), min(ty, ey) - (15 if across else 0),
                    w, h, GAUGE, GAUGE_EDGE, 2, data={"gauge": g.name, "part": "body"}))
    out.append(line(fx, fy, tx, ty, INK, 3.5, data={"gauge": g.name, "part": "plunger"}))
    px, py = (0.0, 9.0) if across else (9.0, 0.0)  # the face: a mark across the plunger
    out.append(line(fx - px, fy - py, fx + px, fy + py, FACE, 4))
    out.append(text((tx + ex) / 2, (ty + ey) / 2 + 6, g.name, 17, anchor="middle",
                    weight="bold", data={"gauge": g.name, "part": "name"}))
    # the leg's way for a positive reading: toward the gauge, beside the plunger
    sx, sy = (0.0, 24.0 * other) if across else (-24.0 * other, 0.0)
    m0 = _screen(ua * (R_BAR + 4), ub * (R_BAR + 4))
    m1 = _screen(ua * (R_BAR + 32), ub * (R_BAR + 32))
    out.append(arrow(m0[0] + sx, m0[1] + sy, m1[0] + sx, m1[1] + sy, MOVE, 2.5,
                     data={"gauge": g.name, "part": "positive"}))
    # the face's name by the body, and "reversed" beside it for a reversed mount:
    # above a body beside the bar (higher where the positive arrow runs above the
    # plunger), right of one above or below it
    words = [f"{g.face} face", *(["(reversed)"] if g.reversed else [])]
    lift = 18.0 if sy < 0 else 0.0
    for n, word in enumerate(words):
        if across:  # the last line nearest the body
            out.append(text(ex, ey - 24 - lift - 16 * (len(words) - 1 - n), word, 13, fill=FACE,
                            weight="bold",
                            anchor="end" if ua > 0 else "start"))
        else:  # right of the body, stacked downward
            out.append(text(ex + 22, (ty + ey) / 2 + 5 + 16 * n, word, 13, fill=FACE,
                            weight="bold"))
    out.append("</g>")
    return "".join(out)


def _stand(tx: float, ty: float, ex: float, ey: float, across: bool) -> str:
    """The stand holding a gauge: a post from the gauge's body to a base block, away
    from the leg (down from a gauge beside the bar)."""
    if across:
        x = ex + (10 if ex < tx else -10)  # at the body's outer end
        return line(x, ty, x, ty + 52, MUTED, 4) + rect(x - 18, ty + 52, 36, 10, MUTED) + \
            text(x, ty + 78, "stand", 12, anchor="middle", fill=MUTED)
    up = ey < ty
    end = ey - 14 if up else ey + 14
    block_y = end - 10 if up else end
    return line(ex, ey, ex, end, MUTED, 4) + rect(ex - 18, block_y, 36, 10, MUTED) + \
        text(ex - 24, block_y + 9, "stand", 12, anchor="end", fill=MUTED)


# --- the gauges in words, and their preload windows ---------------------------------------


def _gauge_rows(sheet: MountingSheet) -> str:
    out = [line(20, ROWS - 30, 940, ROWS - 30, "#d0d5dd", 1)]
    for n, g in enumerate(sheet.gauges):
        y = ROWS + ROW * n
        rev = " (a reversed mount)" if g.reversed else ""
        out.append(text(20, y, f"{g.name}: along {g.face}{rev}", 16, weight="bold",
                        data={"gauge": g.name, "part": "row"}))
        out.append(text(20, y + 20, f"on the leg's {g.face} side, plunger pointing "
                                    f"{g.pointing} onto the {g.face} face", 13))
        out.append(text(20, y + 38, f"reads + as the leg moves {g.face} (the plunger "
                                    "goes in)", 13, fill=MOVE))
        out.append(_window_bar(g, 560, 900, y))
    return "".join(out)


def _window_bar(g: GaugeMount, x0: float, x1: float, y: float) -> str:
    """The plunger's stroke from 0 (out) to its end (in), the window the plan check
    allows shaded, the config's preload marked."""
    k = (x1 - x0) / g.stroke_mm
    out = [rect(x0, y + 6, x1 - x0, 14, "#ffffff", INK, 1)]
    if g.window_mm is not None:
        lo, hi = g.window_mm
        out.append(rect(x0 + lo * k, y + 6, (hi - lo) * k, 14, WINDOW, MOVE, 1.5,
                        data={"gauge": g.name, "part": "window",
                              "window": f"{lo:.2f}-{hi:.2f}"}))
        words = f"push in {lo:.2f}–{hi:.2f} mm"
    else:
        words = f"push in {g.preload_mm:.2f} mm (the plan is not checked)"
    xq = x0 + g.preload_mm * k
    out.append(line(xq, y + 2, xq, y + 24, INK, 2.5))
    out.append(text(x0 - 6, y + 18, "0", 12, anchor="end", fill=MUTED))
    out.append(text(x1 + 6, y + 18, f"{_num(g.stroke_mm)} mm", 12, fill=MUTED))
    out.append(text(x0, y - 4, f"{g.name}: {words}", 14, weight="bold",
                    data={"gauge": g.name, "part": "window-label"}))
    out.append(text(x0, y + 38, f"of its stroke; the black mark: the config's preload, "
                                f"{g.preload_mm:.2f} mm", 12, fill=MUTED))
    return "".join(out)


def draw(sheet: MountingSheet) -> str:
    """The mounting's picture, a standalone SVG document (text)."""
    names = ", ".join(g.name for g in sheet.gauges)
    height = int(ROWS + ROW * len(sheet.gauges) + 10)
    where = "at its middle" if sheet.middle else f"at {sheet.at:g} of its length"
    title = f"Mounting {sheet.setup + 1}: gauges {names} on leg {sheet.leg}, {where}"
    body = [rect(0, 0, WIDTH, height, "#ffffff"),
            text(20, 30, title, 20, weight="bold"),
            text(20, 52, "At Π0, stands fixed to the base, every other gauge removed; "
                         "both plungers square to the bar on the gauges' side,", 13,
                 fill=MUTED),
            text(20, 68, f"the same bar at every mounting of leg {sheet.leg} (the bows "
                         "carried from a second gauge plane are that bar's).", 13,
                 fill=MUTED),
            _side_view(sheet), _section(sheet), _gauge_rows(sheet)]
    return (f'<svg xmlns="http://www.w3.org/2000/svg" width="{WIDTH}" height="{height}" '
            f'viewBox="0 0 {WIDTH} {height}" font-family="{FONT}" role="img" '
            f'data-setup="{sheet.setup + 1}" data-leg="{sheet.leg}">'
            f"<title>{escape(title)}</title>{''.join(body)}</svg>\n")
