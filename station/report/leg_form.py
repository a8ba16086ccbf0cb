"""The legs' bows in the report (docs/model.md, "Leg form against tilts and gaps"):
where a second gauge plane let the fit take each gauge plane's bow (``bow_xy`` …
``bow_zy`` in ``identified``), the summary's line and report.html's table beside
the gaps, each with its standard error. Every field may be missing (a run with one
gauge plane, a result from before the bows): then nothing is said."""

from __future__ import annotations

from station.record.result import RunResult
from station.report.format import at, param_html

#: FIT_NAMES' bows, spelled out: the report is read without the maths loaded.
BOWS = ("bow_xy", "bow_xz", "bow_yx", "bow_yz", "bow_zx", "bow_zy")


def _rows(result: RunResult) -> list[tuple[str, float, float | None]]:
    """(name, sagitta mm, its standard error) of every bow the result states."""
    out = []
    for name in BOWS:
        v = at(result.identified, name)
        if v is not None:
            out.append((name, v, at(result.std_errors, name)))
    return out


def summary_lines(result: RunResult) -> list[str]:
    """The summary's "legs' bows" line (µm, ± one standard error)."""
    rows = _rows(result)
    if not rows:
        return []
    text = ", ".join(f"{n[4:].upper()} {1000 * v:+.1f}".replace("-", "−")
                     + ("" if s is None else f" ± {1000 * s:.1f}") for n, v, s in rows)
    return [f"  legs' bows    {text} µm (± 1 σ; leg and gauge direction; read in two gauge "
            "planes, told from the tilts; the legs' form, not the machine's geometry: "
            "nothing to write)"]


def html_section(result: RunResult) -> str:
    """report.html's "The legs' form" table; empty without bows."""
    rows = _rows(result)
    if not rows:
        return ""
    table = "".join(
        f"<tr><td class=\"l\">{param_html(n)}: leg {n[4]}, along {n[5]}</td>"
        f"<td class=\"num\">{1000 * v:+.1f}</td>"
        f"<td class=\"num\">{'—' if s is None else f'{1000 * s:.1f}'}</td></tr>"
        for n, v, s in rows)
    return ("<h3>The legs' form</h3>"
            "<table><thead><tr><th class=\"l\">gauge plane</th><th>bow (µm)</th>"
            "<th>σ (µm)</th></tr></thead><tbody>" + table + "</tbody></table>"
            '<p class="small">Each bow is the sagitta of the leg\'s surface where that gauge '
            "touches it, 4·h·t·(1 − t) along the leg. With the gauges at the legs' middles "
            "alone a uniform bow is exactly a tilt of the axes; read in a second plane too, "
            "the fit tells them apart and states both. The bows are the legs' form, not the "
            "machine's geometry: the tool does not see them and nothing is written.</p>")
