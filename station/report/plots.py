"""The report's figures: deviations and identified parameters as inline SVG
(matplotlib, imported on demand)."""

from __future__ import annotations

import contextlib
import io
import re
from collections.abc import Mapping
from typing import Any

from station.report.format import (
    AXES,
    as_dict,
    dev_keys,
    dev_parts,
    dev_tex,
    fmt,
    machine_parameters,
    num,
    param_tex,
    params_of,
    true_value,
    unit,
)

# ---------------------------------------------------------------------- plots


def pyplot():
    # Imported on demand: matplotlib costs ~0.5 s, and `orthocal identify` or
    # summary_text must not pay for it. Agg first: the station has no display.
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def to_svg(fig) -> str:
    """The figure as inline SVG, cropped to what it draws (as bbox_inches="tight"
    would, plus its 0.1 inch pad). Tight saving lays the figure out twice, a
    second of the operator's wait at the end of every run; here it is drawn once,
    by one SVG renderer (as savefig's would), and its extent is taken from that
    same renderer, whose text metrics the drawing has already cached, instead of
    measuring every label again with a raster renderer (13-17 % less CPU per
    figure, best of 30; BENCHMARKS.md)."""
    from matplotlib.backends.backend_svg import RendererSVG

    plt = pyplot()
    try:
        buf = io.StringIO()
        width, height = (float(v) for v in fig.get_size_inches())
        image_dpi = fig.dpi
        fig.dpi = 72  # SVG user units are points, as savefig draws it
        renderer = RendererSVG(72 * width, 72 * height, buf, image_dpi=image_dpi,
                               metadata={"Date": None})
        fig.draw(renderer)
        box = fig.get_tightbbox(renderer).padded(0.1)
        renderer.finalize()
    finally:
        plt.close(fig)
    svg = buf.getvalue()
    # Drop the XML prolog and DOCTYPE (not valid inside HTML, and the DOCTYPE
    # names an external DTD) and fix the size so CSS can scale it to the page.
    svg = svg[svg.index("<svg") :]
    svg = re.sub(r"<metadata>.*?</metadata>", "", svg, flags=re.S)
    svg = re.sub(r'(<svg[^>]*?)\swidth="[^"]*"\s+height="[^"]*"', r"\1", svg, count=1)
    # SVG user units are points, y down from the figure's top edge.
    view = (f"{72 * box.x0:.2f} {72 * (height - box.y1):.2f} "
            f"{72 * box.width:.2f} {72 * box.height:.2f}")
    return re.sub(r'viewBox="[^"]*"', f'viewBox="{view}"', svg, count=1)


_C_BEFORE, _C_MODEL, _C_AFTER, _C_TRUTH = "#1f5fa8", "#e08a00", "#2e8b3d", "#c0392b"


def plot_deviations(result: Mapping[str, Any]) -> str | None:
    before = as_dict(result.get("deviations"))
    ver = as_dict(result.get("verification"))
    after = as_dict(ver.get("deviations"))
    keys = dev_keys(before, after)
    if not keys:
        return None
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(10, 4.6))
    # A gap between legs so the three setups read as three groups.
    xs, leg_spans = [], {}
    for i, key in enumerate(keys):
        parts = dev_parts(key)
        group = AXES.index(parts[1]) if parts else 3
        x = i + 0.7 * group
        xs.append(x)
        leg_spans.setdefault(group, []).append(x)

    def series(table, field, offset):
        pts = [(x + offset, num(as_dict(table.get(k)).get(field)))
               for x, k in zip(xs, keys, strict=True)]
        return [p for p in pts if p[1] is not None]

    def errs(table, offset):
        out = []
        for x, k in zip(xs, keys, strict=True):
            row = as_dict(table.get(k))
            m = num(row.get("mean"))
            if m is not None:
                out.append((x + offset, m, num(row.get("std")) or 0.0))
        return out

    handles = []
    pts = errs(before, -0.22)
    if pts:
        handles.append(ax.errorbar(
            [p[0] for p in pts], [p[1] for p in pts], yerr=[p[2] for p in pts],
            fmt="o", color=_C_BEFORE, ms=6, capsize=3, lw=1.2,
            label="before: measured (mean ± std)",
        ))
    pts = series(before, "model", 0.0)
    if pts:
        handles.append(ax.plot(
            [p[0] for p in pts], [p[1] for p in pts], "D", color=_C_MODEL, ms=6, mfc="none",
            mew=1.6, label="before: model fit",
        )[0])
    pts = errs(after, 0.22)
    if pts:
        handles.append(ax.errorbar(
            [p[0] for p in pts], [p[1] for p in pts], yerr=[p[2] for p in pts],
            fmt="s", color=_C_AFTER, ms=6, capsize=3, lw=1.2,
            label="after: verification (mean ± std)",
        ))
    ax.axhline(0.0, color="#555", lw=0.8)
    ax.set_xticks(xs, [dev_tex(k) for k in keys], fontsize=9)
    ax.set_ylabel("deviation (mm)")
    ax.set_xlim(min(xs) - 0.6, max(xs) + 0.6)
    for group, span in leg_spans.items():
        if group < 3:
            ax.axvspan(min(span) - 0.45, max(span) + 0.45, color="#f2f4f7" if group % 2 else
                       "#ffffff", zorder=0)
            ax.text((min(span) + max(span)) / 2, 1.01, f"leg {AXES[group]}",
                    transform=ax.get_xaxis_transform(), ha="center", va="bottom",
                    fontsize=10, fontweight="bold")
    ax.grid(axis="y", color="#ddd", lw=0.6)
    ax.set_axisbelow(True)
    if handles:
        ax.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.17),
                  ncol=len(handles), frameon=False, fontsize=9, columnspacing=1.2)
    return to_svg(fig)


def plot_parameters(result: Mapping[str, Any]) -> str | None:
    names = params_of(result)
    if not names:
        return None
    ident = machine_parameters(result)
    errs = as_dict(result.get("std_errors"))
    ver = as_dict(result.get("verification"))
    v_ident, v_errs = as_dict(ver.get("identified")), as_dict(ver.get("std_errors"))
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(10, 3.8))
    xs = list(range(len(names)))
    handles = []
    # With six parameters the labels no longer fit between the bars and cover each
    # other; the full model's σ is large enough to read from the bars, and the table
    # below has the numbers.
    annotate = len(names) <= 3

    # Tilts are angles (mrad): on their own axis at the right, not on the mm scale.
    ax_tilt = ax.twinx() if any(unit(n) == "mrad" for n in names) else None

    def axis_of(n: str):
        return ax_tilt if ax_tilt is not None and unit(n) == "mrad" else ax

    def draw(values, sigmas, offset, color, marker, label, above=True):
        drawn = False
        for x, n in zip(xs, names, strict=True):
            ax = axis_of(n)
            v, s = num(values.get(n)), num(sigmas.get(n))
            if v is None:
                continue
            if s is not None:
                # Thin bar ±3σ (where the true value almost surely is), thick ±1σ.
                ax.plot([x + offset] * 2, [v - 3 * s, v + 3 * s], color=color, lw=1.2,
                        solid_capstyle="butt")
                ax.plot([x + offset] * 2, [v - s, v + s], color=color, lw=5, alpha=0.55,
                        solid_capstyle="butt")
            ax.plot([x + offset], [v], marker, color=color, ms=7, mec="white", mew=0.8,
                    zorder=3)
            # σ is often far smaller than the axis range and the bars vanish into the
            # marker; the number next to it still tells the reader how sure we are.
            drawn = True
            if not annotate:
                continue
            label_text = fmt(v, signed=True) + (f" ± {fmt(s)}" if s is not None else "")
            # Beyond the end of the ±3σ bar on a white ground: beside the marker the
            # text would cross the truth bar, the zero line and the neighbouring series.
            # "before" goes above and "after" below, so the two never collide.
            reach = 3 * s if s is not None else 0.0
            ax.annotate(label_text, (x + offset, v + reach if above else v - reach),
                        xytext=(0, 5 if above else -5), textcoords="offset points",
                        va="bottom" if above else "top", ha="center", fontsize=8,
                        color=color, zorder=4,
                        bbox={"fc": "white", "ec": "none", "alpha": 0.85, "pad": 0.8})
        if drawn:
            handles.append(ax.plot([], [], marker, color=color, ms=7, label=label)[0])

    draw(ident, errs, -0.12 if v_ident else 0.0, _C_BEFORE, "o",
         "identified before calibration")
    if v_ident:
        draw(v_ident, v_errs, 0.12, _C_AFTER, "s",
             "re-identified after calibration (Δρ should be ≈ 0)" if ax_tilt is not None
             else "re-identified after calibration (should be ≈ 0)", above=False)
    truth = [(x, true_value(result, n), n) for x, n in zip(xs, names, strict=True)]
    truth = [t for t in truth if t[1] is not None]
    for x, t, n in truth:
        line = axis_of(n).plot([x - (0.12 if v_ident else 0.0)], [t], "_", color=_C_TRUTH,
                               ms=22, mew=2.2, zorder=2,
                               label="hidden truth of the simulated machine")[0]
    if truth:
        handles.append(line)
    handles.append(ax.plot([], [], color="#777", lw=5, alpha=0.55, label="±1σ")[0])
    handles.append(ax.plot([], [], color="#777", lw=1.2, label="±3σ")[0])
    ax.axhline(0.0, color="#555", lw=0.8)
    ax.set_xticks(xs, [param_tex(n) for n in names], fontsize=11)
    ax.set_xlim(-0.6, len(names) - 0.4)
    ax.margins(y=0.2)  # room for the value labels beyond the outermost bars
    ax.set_ylabel("value (mm)")
    if ax_tilt is not None:
        first_tilt = next(x for x, n in zip(xs, names, strict=True) if unit(n) == "mrad")
        ax.axvline(first_tilt - 0.5, color="#999", lw=0.8, ls=":")
        ax_tilt.axhline(0.0, color="#555", lw=0.8, ls=":")
        ax_tilt.margins(y=0.2)
        ax_tilt.set_ylabel("tilt (mrad)")
    ax.grid(axis="y", color="#ddd", lw=0.6)
    ax.set_axisbelow(True)
    ax.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.12), ncol=3,
              frameon=False, fontsize=9)
    return to_svg(fig)


# ----------------------------------------------------------------------- html


def release_fonts() -> None:
    """Close the font files matplotlib keeps open in its caches.

    Its font and mathtext caches hold every TrueType file open for the life of the
    process; in a long-lived station (and under the tests' leak check) that reads as
    leaked descriptors. A report is drawn once per run, so re-reading the fonts next
    time costs nothing that matters. Private API, hence the guarded lookups.
    """
    import gc

    from matplotlib import font_manager, mathtext

    for cached in (getattr(font_manager, "_get_font", None),
                   getattr(getattr(mathtext, "MathTextParser", None), "_parse_cached", None)):
        clear = getattr(cached, "cache_clear", None)
        if clear is not None:
            clear()
    gc.collect()


# ------------------------------------------------------------ accuracy at the tool


def _levels(values: Any) -> Any:
    """Distinct grid levels (rounded to 1 µm: the result stores 4 decimals)."""
    import numpy as np

    return np.unique(np.round(values, 3))


def _edges(levels: Any) -> Any:
    """Cell edges midway between levels, half a spacing beyond the ends."""
    import numpy as np

    if len(levels) == 1:
        return np.array([levels[0] - 0.5, levels[0] + 0.5])
    mid = (levels[1:] + levels[:-1]) / 2
    return np.concatenate([[2 * levels[0] - mid[0]], mid, [2 * levels[-1] - mid[-1]]])


def _nice(value: float) -> float:
    """1, 2 or 5 × 10ⁿ at most ``value``: the scale arrow's length in µm."""
    import math

    if value <= 0:
        return 1.0
    exp = math.floor(math.log10(value))
    for step in (5, 2, 1):
        if step * 10**exp <= value:
            return float(step * 10**exp)
    return float(10**exp)


def plot_field(acc: Mapping[str, Any]) -> str | None:
    """The tool-point error field over the workspace: three horizontal slices of
    the grid (lowest, middle, highest z), before (top) and after (bottom); colour
    |E| (µm, each row on its own scale: before is ten times after), arrows the x–y
    part with a scale arrow. None when the result has no usable field."""
    import numpy as np

    field = as_dict(acc.get("field"))
    try:
        pts = np.asarray(field.get("points_mm"), dtype=float)
        rows = [(label, np.asarray(field.get(key), dtype=float)) for key, label in
                (("before_mm", "before"), ("after_mm", "after"))
                if field.get(key) is not None]
    except (TypeError, ValueError):
        return None
    if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) == 0 or not np.all(np.isfinite(pts)):
        return None
    rows = [(lbl, e) for lbl, e in rows if e.shape == pts.shape and np.all(np.isfinite(e))]
    if not rows:
        return None
    # The geometry in the controller: |E| expected per point, no direction (its
    # mean field is zero; what is left is the identification's error).
    comp = as_dict(acc.get("compensated")).get("field_rms_mm")
    with contextlib.suppress(TypeError, ValueError):
        mags = np.asarray(comp, dtype=float) if comp is not None else None
        if mags is not None and mags.shape == (len(pts),) and np.all(np.isfinite(mags)):
            rows.append(("compensated", mags))
    zs = _levels(pts[:, 2])
    slices = sorted({float(zs[0]), float(zs[len(zs) // 2]), float(zs[-1])})
    xs, ys = _levels(pts[:, 0]), _levels(pts[:, 1])
    xe, ye = _edges(xs), _edges(ys)
    spacing = min(float(np.min(np.diff(xs))) if len(xs) > 1 else 1.0,
                  float(np.min(np.diff(ys))) if len(ys) > 1 else 1.0)
    ix = np.searchsorted(xs, np.round(pts[:, 0], 3))
    iy = np.searchsorted(ys, np.round(pts[:, 1], 3))
    iz = np.round(pts[:, 2], 3)
    titles = {"before": "before calibration", "after": "after calibration",
              "compensated": "geometry in the\ncontroller (expected)"}

    plt = pyplot()
    from matplotlib import colormaps

    # Ten steps: a reader matches a cell to the bar by eye, and the bar stays
    # vector (matplotlib embeds a PNG for a bar of 50 colours or more).
    cmap = colormaps["YlOrRd"].resampled(10)
    n = len(slices)
    # A fixed grid with a narrow colour-bar column: constrained layout would cost
    # more than the rest of the figure together, with the operator waiting.
    fig, grid_axes = plt.subplots(
        len(rows), n + 1, figsize=(10, 3.2 * len(rows) + 0.2), squeeze=False,
        gridspec_kw={"width_ratios": [1.0] * n + [0.05], "wspace": 0.08, "hspace": 0.3})
    for r, (label, err) in enumerate(rows):
        axes, cax = grid_axes[r][:n], grid_axes[r][n]
        arrows = err.ndim == 2
        um_err = 1000.0 * err
        mag = np.linalg.norm(um_err, axis=1) if arrows else um_err
        xy = np.linalg.norm(um_err[:, :2], axis=1) if arrows else np.zeros(1)
        vmax = float(mag.max()) if mag.max() > 0 else 1.0
        # The longest x–y arrow spans 0.9 cells: arrows of a row compare, and stay
        # inside their neighbourhood.
        longest = float(xy.max()) if xy.max() > 0 else 1.0
        scale = longest / (0.9 * spacing)
        mesh = q = None
        for c, z in enumerate(slices):
            ax = axes[c]
            sel = np.isclose(iz, z)
            cells = np.full((len(ys), len(xs)), np.nan)
            cells[iy[sel], ix[sel]] = mag[sel]
            mesh = ax.pcolormesh(xe, ye, np.ma.masked_invalid(cells), cmap=cmap,
                                 vmin=0.0, vmax=vmax, shading="flat")
            if arrows:
                q = ax.quiver(pts[sel, 0], pts[sel, 1], um_err[sel, 0], um_err[sel, 1],
                              angles="xy", scale_units="xy", scale=scale, width=0.006,
                              color="#1d2330", pivot="middle")
            ax.set_xlim(xe[0], xe[-1])
            ax.set_ylim(ye[0], ye[-1])
            ax.set_aspect("equal", adjustable="box")
            ax.set_title(f"z = {z:g} mm".replace("-", "−"), fontsize=10, loc="left")
            ax.tick_params(labelsize=8)
            ax.set_xlabel("x (mm)", fontsize=9)
            if c == 0:
                ax.set_ylabel(f"{titles[label]}\ny (mm)", fontsize=9)
            else:
                ax.tick_params(labelleft=False)
        bar = fig.colorbar(mesh, cax=cax)
        bar.set_label("|E| (µm)", fontsize=9)
        cax.tick_params(labelsize=8)
        if not arrows:
            continue
        key = _nice(longest)
        axes[-1].quiverkey(q, 1.0, 1.06, key, f"arrow {key:g} µm (x–y)", labelpos="W",
                           coordinates="axes", fontproperties={"size": 8})
    return to_svg(fig)
