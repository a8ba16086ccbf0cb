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


C_BEFORE, C_MODEL, C_AFTER, C_TRUTH = "#1f5fa8", "#e08a00", "#2e8b3d", "#c0392b"


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
              offset: float) -> list[tuple[float, float]]:
    """(x, mean) of each deviation of ``table`` measured (their spread over the cycles
    is the table's: a figure of the page draws 95 % intervals only)."""
    out = []
    for x, k in zip(xs, keys, strict=True):
        m = num(table[k].mean) if k in table else None
        if m is not None:
            out.append((x + offset, m))
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
        handles.append(ax.plot(
            [p[0] for p in pts], [p[1] for p in pts], "o", color=C_BEFORE, ms=6,
            label="before: measured (mean of the cycles)",
        )[0])
    fitted = _modelled(before, xs, keys)
    if fitted:
        handles.append(ax.plot(
            [p[0] for p in fitted], [p[1] for p in fitted], "D", color=C_MODEL, ms=6,
            mfc="none", mew=1.6, label="before: model fit",
        )[0])
    pts = _measured(after, xs, keys, 0.22)
    if pts:
        handles.append(ax.plot(
            [p[0] for p in pts], [p[1] for p in pts], "s", color=C_AFTER, ms=6,
            label="after: verification (mean of the cycles)",
        )[0])
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
class Parameters:
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

    def draw(self, values: Mapping[str, float | None], halves: Mapping[str, float | None],
             offset: float, color: str, marker: str, label: str, above: bool = True,
             texts: Mapping[str, str] | None = None) -> None:
        """Each parameter's value with its 95 % interval as a bar (``halves``: the
        half-widths), and beside it, when few, ``texts`` (else the value ± half)."""
        drawn = False
        for x, n in enumerate(self.names):
            ax = self.axis_of(n)
            v, h = at(values, n), at(halves, n)
            if v is None:
                continue
            if h is not None:
                ax.plot([x + offset] * 2, [v - h, v + h], color=color, lw=3, alpha=0.6,
                        solid_capstyle="butt")
            ax.plot([x + offset], [v], marker, color=color, ms=7, mec="white", mew=0.8,
                    zorder=3)
            drawn = True
            if self.annotate:
                text = (texts or {}).get(n) or (
                    fmt(v, signed=True) + (f" ± {fmt(h)}" if h is not None else ""))
                self._label(ax, x + offset, v, h, text, color, above)
        if drawn:  # on the axis of the last parameter drawn, as the figures always had it
            self.handles.append(ax.plot([], [], marker, color=color, ms=7, label=label)[0])

    @staticmethod
    def _label(ax: Any, x: float, v: float, h: float | None, text: str, color: str,
               above: bool) -> None:
        # The interval is often far smaller than the axis range and the bar vanishes
        # into the marker; the number next to it still tells the reader how sure we are.
        # Beyond the end of the bar on a white ground: beside the marker the text would
        # cross the truth bar, the zero line and the neighbouring series. "before" goes
        # above and "after" below, so the two never collide.
        reach = h if h is not None else 0.0
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
            line = self.axis_of(n).plot([x + offset], [t], "_", color=C_TRUTH, ms=22,
                                        mew=2.2, zorder=2,
                                        label="hidden truth of the simulated machine")[0]
        if truth:
            self.handles.append(line)

    def finish(self, plt: Any, fig: Any, bar: str) -> str:
        """The axes labelled, the legend (``bar``: what each bar is), the SVG."""
        ax, names = self.ax, self.names
        self.handles.append(ax.plot([], [], color="#777", lw=3, alpha=0.6, label=bar)[0])
        ax.axhline(0.0, color="#555", lw=0.8)
        ax.set_xticks(list(range(len(names))), [param_tex(n) for n in names], fontsize=11)
        ax.set_xlim(-0.6, len(names) - 0.4)
        ax.margins(y=0.2)  # room for the value labels beyond the outermost bars
        ax.set_ylabel("value (mm)")
        if self.ax_tilt is not None:
            first_tilt = next(x for x, n in enumerate(names) if unit(n) == "mrad")
            ax.axvline(first_tilt - 0.5, color="#999", lw=0.8, ls=":")
            self.ax_tilt.axhline(0.0, color="#555", lw=0.8, ls=":")
            self.ax_tilt.margins(y=0.2)
            self.ax_tilt.set_ylabel("tilt (mrad)")
        ax.grid(axis="y", color="#ddd", lw=0.6)
        ax.set_axisbelow(True)
        ax.legend(handles=self.handles, loc="upper center", bbox_to_anchor=(0.5, -0.12),
                  ncol=3, frameon=False, fontsize=9)
        return to_svg(fig)


def _halves(se: Mapping[str, float | None], dof: float | None) -> dict[str, float | None]:
    """A record from before the statement: each standard error's 95 % half-width, k
    from Student's t on the identification's dof (the legacy path; a record with a
    statement draws its own expanded uncertainties, station.report.statement_figure)."""
    from orthocal import coverage_factor

    k = coverage_factor(num(dof))
    return {n: None if (s := num(v)) is None else k * s for n, v in se.items()}


def plot_parameters(result: RunResult) -> str | None:
    """A record from before the statement: the identified parameters with their 95 %
    intervals (a record with a statement: station.report.statement_figure)."""
    names = params_of(result)
    if not names:
        return None
    ver = result.verification
    v_ident = ver.identified if ver is not None else {}
    v_half = _halves(ver.std_errors, ver.std_errors_dof) if ver is not None else {}
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(10, 3.8))
    p = Parameters(ax, ax.twinx() if any(unit(n) == "mrad" for n in names) else None,
                   names, annotate=len(names) <= 3)
    p.draw(machine_parameters(result), _halves(result.std_errors, result.std_errors_dof),
           -0.12 if v_ident else 0.0, C_BEFORE, "o", "identified before calibration")
    if v_ident:
        p.draw(v_ident, v_half, 0.12, C_AFTER, "s",
               "re-identified after calibration (Δρ should be ≈ 0)" if p.ax_tilt is not None
               else "re-identified after calibration (should be ≈ 0)", above=False)
    p.truth(hidden(result), -0.12 if v_ident else 0.0)
    return p.finish(plt, fig, "95 % interval (±k σ, Student's t)")


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
