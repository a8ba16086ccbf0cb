"""``orthocal history --plot FILE``: a machine's parameters over its runs as one
figure for its maintenance file (docs/design.md, "Machine history"), PNG or SVG.

A panel per joint error e = Δρ − o (µm, the machine's own, whatever offsets were
written in between: station.history.entry), then one for the tilts (mrad) and one
for the gaps (µm) where any run identified them. Each value as found (open circle,
at the run's start) and as left (filled square, at its end) with its 95 % error
bar: the expanded uncertainty of the run's statement (Type A and B: docs/design.md,
"The statement of the machine"), the same ± report.html prints; an entry from before
the statement bars its budget's expanded uncertainty or its scatter's interval, each
labelled as what it is. Each panel states every parameter's drift per month, or why
none (station.history.trend). A footnote says what e is: on a calibrated machine it is
minus the offset the controller holds, not an error left in the machine."""

from __future__ import annotations

import math
import textwrap
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from station.history.trend import Drift, Point, drift, series, why_no_drift
from station.report.format import param_plain
from station.report.plots import pyplot, release_fonts

#: The figure formats, by the file's suffix.
FORMATS = {".png": "png", ".svg": "svg"}

#: (name prefix, what the panel shows, unit, factor from the entry's unit). A panel
#: per joint: their errors differ by hundreds of µm, and a shared scale would flatten
#: the few µm a joint drifts.
GROUPS = (("drho_x", "joint x zero error e = Δρ − o", "µm", 1000.0),
          ("drho_y", "joint y zero error e = Δρ − o", "µm", 1000.0),
          ("drho_z", "joint z zero error e = Δρ − o", "µm", 1000.0),
          ("tilt_", "tilts of the axes", "mrad", 1.0),
          ("gap_", "gaps between the axes", "µm", 1000.0))

#: Under the figure: what e is, since a calibrated machine shows minus the offsets
#: its controller holds (e.g. −1818.6 µm), which alone would read as a machine far off.
E_MEANS = ("e = Δρ − o: each joint's zero error without the controller's offsets o, the "
           "machine's own; the offsets cancel it, so a calibrated machine shows e ≈ −o while "
           "the joint as found, Δρ = e + o, is near 0 (orthocal history lists Δρ). Only e "
           "compares across runs whatever offsets were written, so its drift is the "
           "machine's.")

_COLOURS = ("#1f5fa8", "#e08a00", "#2e8b3d")
#: What each kind of bar is, in the legend (station.history.trend.BASES): one
#: uncertainty per value, the run's statement's, as report.html states it.
BARS = {"statement": "± U 95 % of the run's statement",
        "certificate": "± U 95 % of its budget (a run from before the statement)",
        "scatter": "± 95 % of its scatter alone (a run from before the statement)"}


def _label(name: str) -> str:
    """A parameter's name in a legend: e for the joints (drho_x: the frame's e_x)."""
    return f"e {name[-1]}" if name.startswith("drho_") else param_plain(name)


def _drift_text(name: str, points: Sequence[Point], unit: str, scale: float) -> str:
    d: Drift | None = drift(points)
    if d is None:
        return f"{_label(name)}: drift not stated, {why_no_drift(points)}"
    return (f"{_label(name)}: {scale * d.per_month:+.3g} ± {scale * d.expanded_95:.2g} "
            f"{unit}/month ({d.runs} runs)")


def _panel(ax: Any, names: Sequence[str], points: Mapping[str, list[Point]], title: str,
           unit: str, scale: float) -> None:
    texts = []
    for colour, name in zip(_COLOURS * 2, names, strict=False):
        for state, marker, face in (("as found", "o", "none"), ("as left", "s", colour),
                                    ("measured", "D", colour)):
            # Bars of one kind per legend entry: the run's statement, and (entries
            # from before it) its certificate or its scatter alone, labelled apart.
            for basis, bars in BARS.items():
                chosen = [p for p in points[name] if p.state == state and p.basis == basis]
                if not chosen:
                    continue
                xs = [p.when for p in chosen]
                ys = [scale * p.value for p in chosen]
                err = [math.nan if p.expanded_95 is None else scale * p.expanded_95
                       for p in chosen]
                label = _label(name) + ("" if state == "measured" else f" {state}") + \
                    f", {bars}"
                ax.errorbar(xs, ys, yerr=err, fmt=marker, color=colour, mfc=face, ms=6,
                            capsize=3, lw=1, label=label)
        texts.append(_drift_text(name, points[name], unit, scale))
    ax.set_title(title, fontsize=10, loc="left")
    ax.set_ylabel(unit)
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)
    # Beside the panel, under its legend: over the points it would hide the first run.
    ax.text(1.02, 0.0, "drift per month, ± 95 %:\n" + "\n".join(texts),
            transform=ax.transAxes, va="bottom", ha="left", fontsize=8)


def plot_history(entries: Sequence[Mapping[str, Any]], path: Path, machine_id: str) -> None:
    """Write the figure of ``entries`` (one machine's, oldest first) to ``path``,
    in the format its suffix names (FORMATS). ValueError: nothing to draw."""
    points = series(entries)
    groups = [(prefix, what, unit, scale, [n for n in points if n.startswith(prefix)])
              for prefix, what, unit, scale in GROUPS]
    groups = [g for g in groups if g[4]]
    if not groups:
        raise ValueError("no run states a parameter with its date")
    plt = pyplot()
    # Text as text in the SVG: searchable, and selectable in a maintenance file.
    with plt.rc_context({"svg.fonttype": "none"}):
        fig, axes = plt.subplots(len(groups), 1, sharex=True, squeeze=False,
                                 figsize=(12.0, 0.8 + 2.4 * len(groups)))
        try:
            for ax, (_, what, unit, scale, names) in zip(axes[:, 0], groups, strict=True):
                _panel(ax, names, points, f"machine {machine_id}: {what} ({unit})", unit,
                       scale)
            axes[-1, 0].set_xlabel("run date (UTC)")
            fig.suptitle(f"Calibration history of machine {machine_id}: {len(entries)} runs",
                         fontsize=12)
            fig.autofmt_xdate()
            if groups[0][0].startswith("drho_"):  # the footnote where e is drawn
                # two lines of 8 pt under the panels: 0.45 in of the figure's height
                fig.tight_layout(rect=(0.0, 0.45 / fig.get_figheight(), 1.0, 1.0))
                fig.text(0.01, 0.005, textwrap.fill(E_MEANS, 180), fontsize=8,
                         va="bottom", ha="left")
            else:
                fig.tight_layout()
            fmt = FORMATS[path.suffix.lower()]
            meta = ({"Title": f"orthocal history {machine_id}", "Date": None}
                    if fmt == "svg" else {"Title": f"orthocal history {machine_id}"})
            fig.savefig(path, format=fmt, dpi=150, metadata=meta)
        finally:
            plt.close(fig)
            # As a report does: matplotlib's font caches would hold the font files
            # open for the life of a long-lived process (plots.release_fonts).
            release_fonts()
