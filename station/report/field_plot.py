"""The error field at the tool as report.html's figure (docs/design.md, "Accuracy at
the tool"): the result's ``accuracy.field`` in three horizontal slices of the grid,
before, after and with the geometry in the controller, as inline SVG."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from station.record.result_accuracy import Accuracy
from station.report.plots import pyplot, to_svg

#: The rows' titles, by what they show.
_TITLES = {"before": "before calibration", "after": "after calibration",
           "compensated": "geometry in the\ncontroller (expected)"}


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


def _field_rows(acc: Accuracy) -> tuple[Any, list[tuple[str, Any]]] | None:
    """The grid's points (n × 3, mm) and the rows to draw, each an n × 3 error field
    (before, after) or the n |E| expected with the geometry in the controller; None
    when the points or every field are unusable (ragged, mis-sized or not finite):
    a figure it cannot draw must not cost the operator the rest of the report."""
    import numpy as np

    field = acc.field
    try:
        pts = np.asarray(field.points_mm, dtype=float)
        rows = [(label, np.asarray(values, dtype=float)) for values, label in
                ((field.before_mm, "before"), (field.after_mm, "after"))]
    except ValueError:  # ragged lists
        return None
    if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) == 0 or not np.all(np.isfinite(pts)):
        return None
    rows = [(lbl, e) for lbl, e in rows if e.shape == pts.shape and np.all(np.isfinite(e))]
    if not rows:
        return None
    # The geometry in the controller: |E| expected per point, no direction (its
    # mean field is zero; what is left is the identification's error).
    if acc.compensated is not None:
        mags = np.asarray(acc.compensated.field_rms_mm, dtype=float)
        if mags.shape == (len(pts),) and np.all(np.isfinite(mags)):
            rows.append(("compensated", mags))
    return pts, rows


@dataclass(frozen=True)
class _Slices:
    """The grid cut in horizontal slices (lowest, middle, highest z): each level,
    each cell's edges, and where each point goes."""

    pts: Any  # n × 3, mm
    slices: list[float]
    xs: Any
    ys: Any
    xe: Any
    ye: Any
    ix: Any
    iy: Any
    iz: Any
    spacing: float  # the grid's smallest step in x or y, mm


def _slices(pts: Any) -> _Slices:
    import numpy as np

    zs = _levels(pts[:, 2])
    slices = sorted({float(zs[0]), float(zs[len(zs) // 2]), float(zs[-1])})
    xs, ys = _levels(pts[:, 0]), _levels(pts[:, 1])
    spacing = min(float(np.min(np.diff(xs))) if len(xs) > 1 else 1.0,
                  float(np.min(np.diff(ys))) if len(ys) > 1 else 1.0)
    return _Slices(pts, slices, xs, ys, _edges(xs), _edges(ys),
                   np.searchsorted(xs, np.round(pts[:, 0], 3)),
                   np.searchsorted(ys, np.round(pts[:, 1], 3)),
                   np.round(pts[:, 2], 3), spacing)


def plot_field(acc: Accuracy) -> str | None:
    """The tool-point error field over the workspace: three horizontal slices of
    the grid (lowest, middle, highest z), before (top) and after (bottom); colour
    |E| (µm, each row on its own scale: before is ten times after), arrows the x–y
    part with a scale arrow. None when the result has no usable field."""
    read = _field_rows(acc)
    if read is None:
        return None
    pts, rows = read
    g = _slices(pts)
    plt = pyplot()
    from matplotlib import colormaps

    # Ten steps: a reader matches a cell to the bar by eye, and the bar stays
    # vector (matplotlib embeds a PNG for a bar of 50 colours or more).
    cmap = colormaps["YlOrRd"].resampled(10)
    n = len(g.slices)
    # A fixed grid with a narrow colour-bar column: constrained layout would cost
    # more than the rest of the figure together, with the operator waiting.
    fig, grid_axes = plt.subplots(
        len(rows), n + 1, figsize=(10, 3.2 * len(rows) + 0.2), squeeze=False,
        gridspec_kw={"width_ratios": [1.0] * n + [0.05], "wspace": 0.08, "hspace": 0.3})
    for r, (label, err) in enumerate(rows):
        _field_row(fig, grid_axes[r][:n], grid_axes[r][n], label, err, g, cmap)
    return to_svg(fig)


def _field_row(fig: Any, axes: Any, cax: Any, label: str, err: Any, g: _Slices,
               cmap: Any) -> None:
    """One row of the figure: |E| of ``err`` (n × 3 vectors, or n magnitudes) in each
    slice, its x–y arrows and their scale, and the row's colour bar."""
    import numpy as np

    arrows = err.ndim == 2
    um_err = 1000.0 * err
    mag = np.linalg.norm(um_err, axis=1) if arrows else um_err
    xy = np.linalg.norm(um_err[:, :2], axis=1) if arrows else np.zeros(1)
    vmax = float(mag.max()) if mag.max() > 0 else 1.0
    # The longest x–y arrow spans 0.9 cells: arrows of a row compare, and stay
    # inside their neighbourhood.
    longest = float(xy.max()) if xy.max() > 0 else 1.0
    scale = longest / (0.9 * g.spacing)
    mesh = q = None
    for c, z in enumerate(g.slices):
        ax = axes[c]
        sel = np.isclose(g.iz, z)
        cells = np.full((len(g.ys), len(g.xs)), np.nan)
        cells[g.iy[sel], g.ix[sel]] = mag[sel]
        mesh = ax.pcolormesh(g.xe, g.ye, np.ma.masked_invalid(cells), cmap=cmap,
                             vmin=0.0, vmax=vmax, shading="flat")
        if arrows:
            q = ax.quiver(g.pts[sel, 0], g.pts[sel, 1], um_err[sel, 0], um_err[sel, 1],
                          angles="xy", scale_units="xy", scale=scale, width=0.006,
                          color="#1d2330", pivot="middle")
        ax.set_xlim(g.xe[0], g.xe[-1])
        ax.set_ylim(g.ye[0], g.ye[-1])
        ax.set_aspect("equal", adjustable="box")
        ax.set_title(f"z = {z:g} mm".replace("-", "−"), fontsize=10, loc="left")
        ax.tick_params(labelsize=8)
        ax.set_xlabel("x (mm)", fontsize=9)
        if c == 0:
            ax.set_ylabel(f"{_TITLES[label]}\ny (mm)", fontsize=9)
        else:
            ax.tick_params(labelleft=False)
    bar = fig.colorbar(mesh, cax=cax)
    bar.set_label("|E| (µm)", fontsize=9)
    cax.tick_params(labelsize=8)
    if arrows:
        key = _nice(longest)
        axes[-1].quiverkey(q, 1.0, 1.06, key, f"arrow {key:g} µm (x–y)", labelpos="W",
                           coordinates="axes", fontproperties={"size": 8})
