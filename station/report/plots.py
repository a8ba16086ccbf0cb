"""The report's figures: deviations and identified parameters as inline SVG
(matplotlib, imported on demand)."""

from __future__ import annotations

import io
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from station.record.keys import dev_keys, dev_parts
from station.record.result import Deviation, RunResult, Simulation
from station.report.format import (
    AXES,
    at,
    dev_tex,
    fmt,
    hidden,
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


def _dev_positions(keys: list[str]) -> tuple[list[float], dict[int, list[float]]]:
    """Each deviation's x and each leg's xs (group 3: a key of no leg), with a gap
    between legs so the three setups read as three groups."""
    xs: list[float] = []
    leg_spans: dict[int, list[float]] = {}
    for i, key in enumerate(keys):
        parts = dev_parts(key)
        group = AXES.index(parts[1]) if parts else 3
        x = i + 0.7 * group
        xs.append(x)
        leg_spans.setdefault(group, []).append(x)
    return xs, leg_spans


def _measured(table: Mapping[str, Deviation], xs: list[float], keys: list[str],
              offset: float) -> list[tuple[float, float, float]]:
    """(x, mean, std) of each deviation of ``table`` measured."""
    out = []
    for x, k in zip(xs, keys, strict=True):
        m = num(table[k].mean) if k in table else None
        if m is not None:
            out.append((x + offset, m, num(table[k].std) or 0.0))
    return out


def _modelled(table: Mapping[str, Deviation], xs: list[float],
              keys: list[str]) -> list[tuple[float, float]]:
    """(x, the model's value) of each deviation of ``table`` the model fitted."""
    pts = [(x, num(table[k].model)) for x, k in zip(xs, keys, strict=True) if k in table]
    return [(x, v) for x, v in pts if v is not None]


def _dev_series(ax: Any, before: Mapping[str, Deviation], after: Mapping[str, Deviation],
                xs: list[float], keys: list[str]) -> list[Any]:
    """Before (measured, and the model's fit) and after, drawn; their legend handles."""
    handles = []
    pts = _measured(before, xs, keys, -0.22)
    if pts:
        handles.append(ax.errorbar(
            [p[0] for p in pts], [p[1] for p in pts], yerr=[p[2] for p in pts],
            fmt="o", color=_C_BEFORE, ms=6, capsize=3, lw=1.2,
            label="before: measured (mean ± std)",
        ))
    fitted = _modelled(before, xs, keys)
    if fitted:
        handles.append(ax.plot(
            [p[0] for p in fitted], [p[1] for p in fitted], "D", color=_C_MODEL, ms=6,
            mfc="none", mew=1.6, label="before: model fit",
        )[0])
    pts = _measured(after, xs, keys, 0.22)
    if pts:
        handles.append(ax.errorbar(
            [p[0] for p in pts], [p[1] for p in pts], yerr=[p[2] for p in pts],
            fmt="s", color=_C_AFTER, ms=6, capsize=3, lw=1.2,
            label="after: verification (mean ± std)",
        ))
    return handles


def plot_deviations(result: RunResult) -> str | None:
    before: Mapping[str, Deviation] = result.deviations or {}
    ver = result.verification
    after: Mapping[str, Deviation] = ver.deviations if ver is not None else {}
    keys = dev_keys(before, after)
    if not keys:
        return None
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(10, 4.6))
    xs, leg_spans = _dev_positions(keys)
    handles = _dev_series(ax, before, after, xs, keys)
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


@dataclass
class _Parameters:
    """The parameters' figure as it is drawn: its axes (the tilts, angles in mrad, on
    their own at the right), where each parameter stands, the legend's handles."""

    ax: Any
    ax_tilt: Any
    names: list[str]
    # With six parameters the labels no longer fit between the bars and cover each
    # other; the full model's σ is large enough to read from the bars, and the table
    # below has the numbers.
    annotate: bool
    handles: list[Any] = field(default_factory=list)

    def axis_of(self, n: str) -> Any:
        return self.ax_tilt if self.ax_tilt is not None and unit(n) == "mrad" else self.ax

    def draw(self, values: Mapping[str, float | None], sigmas: Mapping[str, float | None],
             offset: float, color: str, marker: str, label: str, above: bool = True) -> None:
        """Each parameter's value with ±1σ and ±3σ bars (and the numbers, when few)."""
        drawn = False
        for x, n in enumerate(self.names):
            ax = self.axis_of(n)
            v, s = at(values, n), at(sigmas, n)
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
            drawn = True
            if self.annotate:
                self._label(ax, x + offset, v, s, color, above)
        if drawn:  # on the axis of the last parameter drawn, as the figures always had it
            self.handles.append(ax.plot([], [], marker, color=color, ms=7, label=label)[0])

    @staticmethod
    def _label(ax: Any, x: float, v: float, s: float | None, color: str, above: bool) -> None:
        # σ is often far smaller than the axis range and the bars vanish into the
        # marker; the number next to it still tells the reader how sure we are.
        text = fmt(v, signed=True) + (f" ± {fmt(s)}" if s is not None else "")
        # Beyond the end of the ±3σ bar on a white ground: beside the marker the
        # text would cross the truth bar, the zero line and the neighbouring series.
        # "before" goes above and "after" below, so the two never collide.
        reach = 3 * s if s is not None else 0.0
        ax.annotate(text, (x, v + reach if above else v - reach),
                    xytext=(0, 5 if above else -5), textcoords="offset points",
                    va="bottom" if above else "top", ha="center", fontsize=8,
                    color=color, zorder=4,
                    bbox={"fc": "white", "ec": "none", "alpha": 0.85, "pad": 0.8})

    def truth(self, sim: Simulation | None, offset: float) -> None:
        """The simulated machine's hidden value of each parameter, a red bar."""
        truth = [(x, t, n) for x, n in enumerate(self.names)
                 if (t := true_value(sim, n)) is not None]
        for x, t, n in truth:
            line = self.axis_of(n).plot([x + offset], [t], "_", color=_C_TRUTH, ms=22,
                                        mew=2.2, zorder=2,
                                        label="hidden truth of the simulated machine")[0]
        if truth:
            self.handles.append(line)


def plot_parameters(result: RunResult) -> str | None:
    names = params_of(result)
    if not names:
        return None
    ver = result.verification
    v_ident = ver.identified if ver is not None else {}
    v_errs = ver.std_errors if ver is not None else {}
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(10, 3.8))
    p = _Parameters(ax, ax.twinx() if any(unit(n) == "mrad" for n in names) else None,
                    names, annotate=len(names) <= 3)
    p.draw(machine_parameters(result), result.std_errors, -0.12 if v_ident else 0.0,
           _C_BEFORE, "o", "identified before calibration")
    if v_ident:
        p.draw(v_ident, v_errs, 0.12, _C_AFTER, "s",
               "re-identified after calibration (Δρ should be ≈ 0)" if p.ax_tilt is not None
               else "re-identified after calibration (should be ≈ 0)", above=False)
    p.truth(hidden(result), -0.12 if v_ident else 0.0)
    p.handles.append(ax.plot([], [], color="#777", lw=5, alpha=0.55, label="±1σ")[0])
    p.handles.append(ax.plot([], [], color="#777", lw=1.2, label="±3σ")[0])
    ax.axhline(0.0, color="#555", lw=0.8)
    ax.set_xticks(list(range(len(names))), [param_tex(n) for n in names], fontsize=11)
    ax.set_xlim(-0.6, len(names) - 0.4)
    ax.margins(y=0.2)  # room for the value labels beyond the outermost bars
    ax.set_ylabel("value (mm)")
    if p.ax_tilt is not None:
        first_tilt = next(x for x, n in enumerate(names) if unit(n) == "mrad")
        ax.axvline(first_tilt - 0.5, color="#999", lw=0.8, ls=":")
        p.ax_tilt.axhline(0.0, color="#555", lw=0.8, ls=":")
        p.ax_tilt.margins(y=0.2)
        p.ax_tilt.set_ylabel("tilt (mrad)")
    ax.grid(axis="y", color="#ddd", lw=0.6)
    ax.set_axisbelow(True)
    ax.legend(handles=p.handles, loc="upper center", bbox_to_anchor=(0.5, -0.12), ncol=3,
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
