"""The run report: result.json, a self-contained report.html and the short summary.

The input is the result dict of /work/briefs/result_schema.md. Every section may
be missing (a run that failed halfway, no verification, write-back refused), so
everything here reads with ``.get`` and shows "—" rather than raising: a report
that crashes on the failed run is the one report the operator needed most.
"""

from __future__ import annotations

import contextlib
import html
import io
import json
import math
import os
import re
import sys
import tempfile
from collections.abc import Iterable, Mapping
from datetime import datetime
from pathlib import Path
from typing import Any

AXES = ("x", "y", "z")
PARAM_NAMES = ("drho_x", "drho_y", "drho_z", "dL_x", "dL_y", "dL_z")
# Grouped by leg, then posture, then direction: the order an operator measures in
# (one setup per leg), so the plot and the tables read setup by setup.
DEVIATION_KEYS = tuple(
    f"{sign}{leg}{d}" for leg in AXES for sign in "+-" for d in AXES if d != leg
)
# Key order of result.json: the schema's order, so that a person opening the file
# finds status and identified values at the top, not buried alphabetically.
_TOP_ORDER = (
    "run_dir", "status", "message", "started", "finished", "duration_s", "simulated",
    "simulation", "machine", "model", "method", "identified", "std_errors", "correlation",
    "residual_rms_mm", "sigma_mm", "condition_number", "noise_mm", "fit_ok", "fit_note",
    "deviations", "deviations_rms_mm", "setups", "offsets_before", "offsets_written",
    "writeback", "verification", "timing",
)
_MODEL_TEXT = {
    "rho": "joint offsets Δρ only",
    "L": "leg-length errors ΔL only",
    "full": "joint offsets Δρ and leg-length errors ΔL together",
}
_STATUS_TEXT = {
    "ok": "Completed",
    "failed": "Failed",
    "refused": "Write-back refused",
    "aborted": "Aborted",
}
_WRITEBACK_TEXT = {
    "written": "the corrected offsets were written to the controller and read back",
    "refused": "the corrections were NOT written: the station refused them",
    "declined": "the corrections were NOT written: the operator declined",
    "skipped": "the corrections were not written (write-back skipped)",
    "failed-restored": "writing the corrections failed; the previous offsets were restored",
}


# --------------------------------------------------------------------------- json


def _jsonable(value: Any) -> Any:
    """Plain JSON types; NaN/inf become None because json.dumps would emit the
    invalid tokens NaN/Infinity that strict parsers (jq, JavaScript) reject."""
    if isinstance(value, Mapping):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    if isinstance(value, bool) or value is None or isinstance(value, str | int):
        return value
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    # numpy scalars and arrays come from the identification; no numpy import needed.
    if hasattr(value, "tolist"):
        return _jsonable(value.tolist())
    if hasattr(value, "isoformat"):
        return value.isoformat()
    raise TypeError(f"result field of type {type(value).__name__} is not JSON-serialisable")


def jsonable(result: Mapping[str, Any]) -> dict[str, Any]:
    """The result as written to result.json (schema key order, NaN → None), for
    callers that print it, e.g. ``--json``, so stdout and the file agree."""
    return _jsonable(_ordered(result))


def _ordered(result: Mapping[str, Any]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key in _TOP_ORDER:
        if key in result:
            out[key] = result[key]
    for key in sorted(k for k in result if k not in out):
        out[key] = result[key]
    for section in (out, out.get("verification")):
        if isinstance(section, dict) and isinstance(section.get("deviations"), dict):
            devs = section["deviations"]
            section["deviations"] = {k: devs[k] for k in _dev_keys(devs)}
    return out


def _atomic_write(path: Path, text: str) -> None:
    """Write so that a crash leaves either the old file or the new one, never half."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            # mkstemp makes the file private (0600); a report is meant to be read by
            # whoever looks after the machine, not only by the account that ran it.
            os.fchmod(fh.fileno(), 0o644)
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    # The rename itself lives in the directory; without this a power cut can lose it.
    with contextlib.suppress(OSError):
        dir_fd = os.open(path.parent, os.O_RDONLY)
        try:
            os.fsync(dir_fd)
        finally:
            os.close(dir_fd)


def write_result(result: dict, run_dir: Path) -> Path:
    """Write ``run_dir/result.json`` atomically; NaN and infinities become null."""
    path = Path(run_dir) / "result.json"
    data = jsonable(result)
    _atomic_write(path, json.dumps(data, indent=2, ensure_ascii=False, allow_nan=False) + "\n")
    return path


# ------------------------------------------------------------------- formatting


def _num(value: Any) -> float | None:
    if isinstance(value, bool) or value is None:
        return None
    try:
        v = float(value)
    except (TypeError, ValueError):
        return None
    return v if math.isfinite(v) else None


def _fmt(value: Any, digits: int = 3, signed: bool = False) -> str:
    v = _num(value)
    if v is None:
        return "—"
    text = f"{v:+.{digits}f}" if signed else f"{v:.{digits}f}"
    # "−0.000" reads like a real negative value; it is rounding noise.
    if float(text) == 0.0:
        text = f"{0.0:.{digits}f}"
    return text.replace("-", "−")


def _param_plain(name: str) -> str:
    kind, axis = name.split("_", 1)
    return ("Δρ" if kind == "drho" else "ΔL") + axis


def _param_html(name: str) -> str:
    kind, axis = name.split("_", 1)
    return ("Δρ" if kind == "drho" else "ΔL") + f"<sub>{html.escape(axis)}</sub>"


def _param_tex(name: str) -> str:
    kind, axis = name.split("_", 1)
    return (r"$\Delta\rho_" if kind == "drho" else r"$\Delta L_") + axis + "$"


def _dev_parts(key: str) -> tuple[str, str, str] | None:
    """(posture, leg, direction) of "+xy" or of a stroke key such as "+30xy"."""
    if re.fullmatch(r"[+-](\d+(\.\d*)?|\.\d+)?[xyz][xyz]", key):
        return key[:-2], key[-2], key[-1]
    return None


def _posture_html(posture: str, leg: str) -> str:
    if posture in ("+", "-"):
        return f"Π<sub>{leg}</sub><sup>{'+' if posture == '+' else '−'}</sup>"
    return f"Π<sub>{leg}</sub>({posture.replace('-', '−')} mm)"


def _dev_html(key: str) -> str:
    parts = _dev_parts(key)
    if parts is None:
        return html.escape(key)
    sign, leg, d = parts
    return f"{_posture_html(sign, leg)} along {d}"


def _dev_tex(key: str) -> str:
    parts = _dev_parts(key)
    if parts is None:
        return key
    sign, leg, d = parts
    if sign not in ("+", "-"):
        return rf"$\Pi_{leg}({sign})$" + f"\nalong {d}"
    return rf"$\Pi_{leg}^{{{sign}}}$" + f"\nalong {d}"


def _truth(result: Mapping[str, Any], name: str) -> float | None:
    sim = result.get("simulation")
    if not result.get("simulated") or not isinstance(sim, Mapping):
        return None
    kind, axis = name.split("_", 1)
    table = sim.get("true_drho" if kind == "drho" else "true_dl")
    if not isinstance(table, Mapping):
        return None
    return _num(table.get(axis))


def _dict(value: Any) -> dict:
    return value if isinstance(value, dict) else {}


def _params_of(result: Mapping[str, Any]) -> list[str]:
    ident = _dict(result.get("identified"))
    names = [n for n in PARAM_NAMES if n in ident]
    return names + sorted(n for n in ident if n not in PARAM_NAMES)


def _dev_keys(*tables: Mapping[str, Any]) -> list[str]:
    present: set[str] = set()
    for t in tables:
        present.update(t)
    return sorted(present, key=_dev_order)


def _dev_order(key: str) -> tuple:
    """Leg, then posture from ρmax down to ρmin ('+', '+30', '-50', '-'), then
    direction: DEVIATION_KEYS' order, with intermediate strokes in their place."""
    parts = _dev_parts(key)
    if parts is None:
        return (1, key)
    posture, leg, d = parts
    s = {"+": math.inf, "-": -math.inf}.get(posture)
    return (0, leg, -(float(posture) if s is None else s), d)


def _when(iso: Any) -> str:
    if not isinstance(iso, str):
        return "—"
    try:
        dt = datetime.fromisoformat(iso)
    except ValueError:
        return iso
    text = dt.strftime("%Y-%m-%d %H:%M:%S")
    if dt.utcoffset() is not None:
        text += " " + (dt.strftime("%z") or "")
    return text


def _duration(seconds: Any) -> str:
    s = _num(seconds)
    if s is None:
        return "—"
    if s < 60:
        return f"{s:.1f} s"
    minutes, sec = divmod(round(s), 60)
    if minutes < 60:
        return f"{minutes} min {sec:02d} s"
    hours, minutes = divmod(minutes, 60)
    return f"{hours} h {minutes:02d} min"


def _max_abs(devs: Mapping[str, Any]) -> float | None:
    values = [_num(_dict(v).get("mean")) for v in devs.values()]
    finite = [abs(v) for v in values if v is not None]
    return max(finite) if finite else None


# -------------------------------------------------------------------- summary


def _param_line(result: Mapping[str, Any], names: Iterable[str]) -> str:
    ident = _dict(result.get("identified"))
    errs = _dict(result.get("std_errors"))
    return "   ".join(
        f"{_param_plain(n)} = {_fmt(ident.get(n), signed=True)} ± {_fmt(errs.get(n))}"
        for n in names
    )


def summary_text(result: dict) -> str:
    """A few lines for the end of a run: status, identified values, residual,
    offsets written, verification before → after, where the report is."""
    status = str(result.get("status", "unknown"))
    head = f"orthocal run: {_STATUS_TEXT.get(status, status).upper()}"
    if result.get("message"):
        head += f" — {result['message']}"
    lines = [head]
    names = _params_of(result)
    if names:
        lines.append(f"  identified    {_param_line(result, names)} mm")
        noise = _num(result.get("noise_mm"))
        resid = f"  residual      {_fmt(result.get('residual_rms_mm'))} mm RMS"
        if noise is not None:
            resid += f" (indicator noise {_fmt(noise)} mm)"
        if result.get("fit_note"):
            resid += f": {result['fit_note']}"
        lines.append(resid)
    before = _dict(result.get("offsets_before"))
    written = result.get("offsets_written")
    wb = _dict(result.get("writeback"))
    if isinstance(written, dict) and written:
        pairs = ", ".join(
            f"{a} {_fmt(before.get(a))} → {_fmt(written.get(a))}" for a in AXES if a in written
        )
        lines.append(f"  offsets       {pairs} mm ({wb.get('status', 'written')})")
    elif wb:
        reason = f": {wb['reason']}" if wb.get("reason") else ""
        lines.append(f"  offsets       not written ({wb.get('status')}{reason})")
    ver = result.get("verification")
    if isinstance(ver, dict) and ver:
        lines.append(
            f"  verification  deviations RMS {_fmt(result.get('deviations_rms_mm'))} → "
            f"{_fmt(ver.get('deviations_rms_mm'))} mm; re-identified "
            + "  ".join(
                f"{_param_plain(n)} = {_fmt(v, signed=True)}"
                for n, v in _dict(ver.get("identified")).items()
            )
        )
    if result.get("run_dir"):
        lines.append(f"  report        {Path(str(result['run_dir'])) / 'report.html'}")
    return "\n".join(lines)


# ---------------------------------------------------------------------- plots


def _pyplot():
    # Imported on demand: matplotlib costs ~0.5 s, and `orthocal identify` or
    # summary_text must not pay for it. Agg first: the station has no display.
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _svg(fig) -> str:
    plt = _pyplot()
    try:
        buf = io.StringIO()
        fig.savefig(buf, format="svg", bbox_inches="tight", metadata={"Date": None})
    finally:
        plt.close(fig)
    svg = buf.getvalue()
    # Drop the XML prolog and DOCTYPE (not valid inside HTML, and the DOCTYPE
    # names an external DTD) and fix the size so CSS can scale it to the page.
    svg = svg[svg.index("<svg") :]
    svg = re.sub(r"<metadata>.*?</metadata>", "", svg, flags=re.S)
    svg = re.sub(r'(<svg[^>]*?)\swidth="[^"]*"\s+height="[^"]*"', r"\1", svg, count=1)
    return svg


_C_BEFORE, _C_MODEL, _C_AFTER, _C_TRUTH = "#1f5fa8", "#e08a00", "#2e8b3d", "#c0392b"


def _plot_deviations(result: Mapping[str, Any]) -> str | None:
    before = _dict(result.get("deviations"))
    ver = _dict(result.get("verification"))
    after = _dict(ver.get("deviations"))
    keys = _dev_keys(before, after)
    if not keys:
        return None
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(10, 4.6))
    # A gap between legs so the three setups read as three groups.
    xs, leg_spans = [], {}
    for i, key in enumerate(keys):
        parts = _dev_parts(key)
        group = AXES.index(parts[1]) if parts else 3
        x = i + 0.7 * group
        xs.append(x)
        leg_spans.setdefault(group, []).append(x)

    def series(table, field, offset):
        pts = [(x + offset, _num(_dict(table.get(k)).get(field)))
               for x, k in zip(xs, keys, strict=True)]
        return [p for p in pts if p[1] is not None]

    def errs(table, offset):
        out = []
        for x, k in zip(xs, keys, strict=True):
            row = _dict(table.get(k))
            m = _num(row.get("mean"))
            if m is not None:
                out.append((x + offset, m, _num(row.get("std")) or 0.0))
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
    ax.set_xticks(xs, [_dev_tex(k) for k in keys], fontsize=9)
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
    return _svg(fig)


def _plot_parameters(result: Mapping[str, Any]) -> str | None:
    names = _params_of(result)
    if not names:
        return None
    ident = _dict(result.get("identified"))
    errs = _dict(result.get("std_errors"))
    ver = _dict(result.get("verification"))
    v_ident, v_errs = _dict(ver.get("identified")), _dict(ver.get("std_errors"))
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(10, 3.8))
    xs = list(range(len(names)))
    handles = []
    # With six parameters the labels no longer fit between the bars and cover each
    # other; the full model's σ is large enough to read from the bars, and the table
    # below has the numbers.
    annotate = len(names) <= 3

    def draw(values, sigmas, offset, color, marker, label, above=True):
        drawn = False
        for x, n in zip(xs, names, strict=True):
            v, s = _num(values.get(n)), _num(sigmas.get(n))
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
            label_text = _fmt(v, signed=True) + (f" ± {_fmt(s)}" if s is not None else "")
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
             "re-identified after calibration (should be ≈ 0)", above=False)
    truth = [(x, _truth(result, n)) for x, n in zip(xs, names, strict=True)]
    truth = [t for t in truth if t[1] is not None]
    if truth:
        handles.append(ax.plot(
            [t[0] - (0.12 if v_ident else 0.0) for t in truth], [t[1] for t in truth], "_",
            color=_C_TRUTH, ms=22, mew=2.2, zorder=2,
            label="hidden truth of the simulated machine",
        )[0])
    handles.append(ax.plot([], [], color="#777", lw=5, alpha=0.55, label="±1σ")[0])
    handles.append(ax.plot([], [], color="#777", lw=1.2, label="±3σ")[0])
    ax.axhline(0.0, color="#555", lw=0.8)
    ax.set_xticks(xs, [_param_tex(n) for n in names], fontsize=11)
    ax.set_xlim(-0.6, len(names) - 0.4)
    ax.margins(y=0.2)  # room for the value labels beyond the outermost bars
    ax.set_ylabel("value (mm)")
    ax.grid(axis="y", color="#ddd", lw=0.6)
    ax.set_axisbelow(True)
    ax.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.12), ncol=3,
              frameon=False, fontsize=9)
    return _svg(fig)


# ----------------------------------------------------------------------- html

_CSS = """
body{font-family:-apple-system,"Segoe UI",Roboto,"Helvetica Neue",Arial,sans-serif;
 color:#1d2330;max-width:60rem;margin:2rem auto;padding:0 1.2rem;line-height:1.5;font-size:15px}
h1{font-size:1.6rem;margin:0 0 .3rem}
h2{font-size:1.2rem;margin:2rem 0 .6rem;border-bottom:1px solid #d0d5dd;padding-bottom:.2rem}
h3{font-size:1rem;margin:1.2rem 0 .4rem}
.meta{color:#555;margin:0 0 1rem}
.status{display:inline-block;padding:.15rem .7rem;border-radius:1rem;font-weight:600;
 font-size:.95rem;vertical-align:middle;margin-left:.6rem;border:1px solid}
.st-ok{background:#e6f4ea;color:#1e6b30;border-color:#9fd3ab}
.st-failed,.st-aborted{background:#fdecea;color:#a52a1a;border-color:#f0a99f}
.st-refused{background:#fff4e0;color:#8a5300;border-color:#f0c97a}
.box{background:#f6f8fa;border:1px solid #d0d5dd;border-radius:6px;padding:.7rem 1rem;
 margin:.8rem 0}
.warn{background:#fff8e6;border-color:#f0c97a}
.bad{background:#fdecea;border-color:#f0a99f}
table{border-collapse:collapse;margin:.4rem 0 1rem;font-size:.9rem}
th,td{border:1px solid #d0d5dd;padding:.25rem .6rem;text-align:right;vertical-align:top}
th{background:#f0f2f5;font-weight:600}
td.l,th.l{text-align:left}
td.num{font-variant-numeric:tabular-nums;white-space:nowrap}
figure{margin:1rem 0;page-break-inside:avoid;break-inside:avoid}
figure svg{width:100%;height:auto;display:block}
figcaption{font-size:.88rem;color:#444;margin-top:.3rem}
dl.kv{display:grid;grid-template-columns:max-content auto;gap:.15rem 1rem;margin:.4rem 0}
dl.kv dt{color:#555}dl.kv dd{margin:0}
.small{font-size:.85rem;color:#555}
code{font-family:ui-monospace,Menlo,Consolas,monospace;font-size:.88em;word-break:break-all}
@media print{body{margin:0;max-width:none;font-size:11pt}h2{page-break-after:avoid}
 table,.box{page-break-inside:avoid}}
"""


def _e(value: Any) -> str:
    return html.escape(str(value), quote=True)


def _table(head: list[str], rows: list[list[str]], left: int = 1, caption: str = "") -> str:
    """Cells are trusted HTML fragments: callers escape text with _e()."""
    ths = "".join(
        f'<th class="l">{h}</th>' if i < left else f"<th>{h}</th>" for i, h in enumerate(head)
    )
    body = "".join(
        "<tr>" + "".join(
            f'<td class="l">{c}</td>' if i < left else f'<td class="num">{c}</td>'
            for i, c in enumerate(row)
        ) + "</tr>"
        for row in rows
    )
    cap = f'<p class="small">{caption}</p>' if caption else ""
    return f"<table><thead><tr>{ths}</tr></thead><tbody>{body}</tbody></table>{cap}"


def _what_was_done(result: Mapping[str, Any]) -> str:
    setups = result.get("setups") if isinstance(result.get("setups"), list) else []
    cycles = sorted({s.get("cycles_used") for s in setups if isinstance(s, dict)
                     and isinstance(s.get("cycles_used"), int)})
    cyc = ""
    if cycles:
        cyc = (f" ({cycles[0]} cycle{'s' if cycles[0] != 1 else ''} per leg)"
               if len(cycles) == 1 else f" ({cycles[0]}–{cycles[-1]} cycles per leg)")
    model = _MODEL_TEXT.get(str(result.get("model")), str(result.get("model", "—")))
    method = {"linear": "the linearised calibration equations",
              "nonlinear": "the exact kinematic model (iterative least squares)"}.get(
        str(result.get("method")), str(result.get("method", "—")))
    stopped = ""
    if result.get("status") in ("failed", "aborted"):
        # The paragraph below describes the whole procedure; say plainly that this
        # run did not get through it, or a reader takes it for a completed calibration.
        done = len(setups)
        stopped = (f"<p><b>This run stopped early</b>, after measuring {done} of the "
                   "3 legs; see the result below.</p>")
    return stopped + (
        "<p>Two dial indicators were mounted against each leg of the machine in turn. "
        "For each leg the station moved the machine from the <i>mechanical zero</i> "
        "posture Π<sub>0</sub> to the two test postures Π<sub>i</sub><sup>+</sup> and "
        "Π<sub>i</sub><sup>−</sup> (leg i pushed to the end of its stroke each way) and "
        f"back, repeatedly{_e(cyc)}, reading the indicators at every stop. On a perfectly "
        "calibrated machine each leg moves parallel to itself in these postures, so the "
        "indicators read the same everywhere; the 12 differences "
        "(3 legs × 2 postures × 2 indicators), called <i>deviations</i>, show how far the "
        "legs tilt. From them the station estimated, by least squares on "
        f"{_e(method)}, the {_e(model)}.</p>"
        '<p class="small">Δρ<sub>i</sub> (joint offset): how far axis i really is from '
        "where its controller believes it is — an error of the encoder zero. "
        "ΔL<sub>i</sub> (leg-length error): how much leg i is longer than nominal. "
        "± values are one standard error σ; the true value lies within ±3σ with near "
        "certainty if the model is right.</p>"
    )


def _result_paragraph(result: Mapping[str, Any]) -> str:
    status = str(result.get("status"))
    parts: list[str] = []
    names = _params_of(result)
    ident, errs = _dict(result.get("identified")), _dict(result.get("std_errors"))
    if status in ("failed", "aborted"):
        msg = result.get("message") or "no reason recorded"
        parts.append(f"<b>The run did not complete</b>: {_e(msg)}. "
                     "Everything measured up to that point is kept in the run directory; "
                     "the controller's offsets were only changed if stated below.")
    if names:
        vals = "; ".join(
            f"{_param_html(n)} = {_fmt(ident.get(n), signed=True)} ± {_fmt(errs.get(n))} mm"
            for n in names
        )
        what = "joint offsets" if all(n.startswith("drho") for n in names) else "parameters"
        parts.append(f"The {what} were identified as {vals}.")
        resid, noise = _num(result.get("residual_rms_mm")), _num(result.get("noise_mm"))
        if resid is not None:
            s = f"The fitted model reproduces the measured deviations to {_fmt(resid)} mm RMS"
            if noise is not None:
                s += f" (indicator noise: {_fmt(noise)} mm)"
            parts.append(s + ".")
        truths = [(n, _truth(result, n)) for n in names]
        diffs = [abs(_num(ident.get(n)) - t) for n, t in truths
                 if t is not None and _num(ident.get(n)) is not None]
        if diffs:
            parts.append("This was a simulated run; the identified values differ from the "
                         f"virtual machine's hidden ones by at most {_fmt(max(diffs))} mm.")
    wb = _dict(result.get("writeback"))
    if wb.get("status"):
        text = _WRITEBACK_TEXT.get(str(wb["status"]), f"write-back: {wb['status']}")
        reason = f" ({_e(wb['reason'])})" if wb.get("reason") else ""
        parts.append(f"{_e(text[0].upper() + text[1:])}{reason}.")
    ver = _dict(result.get("verification"))
    if ver:
        after = _num(ver.get("deviations_rms_mm"))
        worst = _max_abs(_dict(ver.get("deviations")))
        s = ("A verification measurement shows the legs now parallel to within "
             f"{_fmt(after)} mm RMS")
        if worst is not None:
            s += f" (largest deviation {_fmt(worst)} mm)"
        before = _num(result.get("deviations_rms_mm"))
        if before is not None:
            s += f", against {_fmt(before)} mm RMS before calibration"
        parts.append(s + ".")
    elif names and status == "ok":
        parts.append("No verification measurement was made.")
    if not parts:
        parts.append("No measurement results were recorded.")
    return "<p>" + " ".join(parts) + "</p>"


def _fit_box(result: Mapping[str, Any]) -> str:
    if result.get("residual_rms_mm") is None and not result.get("fit_note"):
        return ""
    rows = [
        ("residual RMS (measured − model)", f"{_fmt(result.get('residual_rms_mm'))} mm"),
        ("σ = √(RSS / (n − p))", f"{_fmt(result.get('sigma_mm'))} mm"),
        ("indicator noise (spread of readings at a stop)", f"{_fmt(result.get('noise_mm'))} mm"),
        ("condition number (sensitivity of the fit to noise)",
         _fmt(result.get("condition_number"), 2)),
        ("deviations RMS before calibration", f"{_fmt(result.get('deviations_rms_mm'))} mm"),
    ]
    dl = "".join(f"<dt>{_e(k)}</dt><dd>{_e(v)}</dd>" for k, v in rows)
    ok = result.get("fit_ok")
    cls = "box" if ok is not False else "box warn"
    verdict = ("The model explains the data: the residual is at the level of the indicator "
               "noise." if ok else "Warning: the residual is larger than the indicator noise "
               "explains; the machine may have errors this model does not include."
               if ok is False else "")
    note = (f"<p><b>Fit quality:</b> {_e(result['fit_note'])}</p>"
            if result.get("fit_note") else "")
    return f'<div class="{cls}">{note}<p>{_e(verdict)}</p><dl class="kv">{dl}</dl></div>'


def _params_table(result: Mapping[str, Any]) -> str:
    names = _params_of(result)
    if not names:
        return "<p>No parameters were identified.</p>"
    ident, errs = _dict(result.get("identified")), _dict(result.get("std_errors"))
    ver = _dict(result.get("verification"))
    v_ident, v_errs = _dict(ver.get("identified")), _dict(ver.get("std_errors"))
    has_truth = any(_truth(result, n) is not None for n in names)
    head = ["parameter", "identified (mm)", "σ (mm)", "±3σ interval (mm)"]
    if has_truth:
        head.append("hidden truth (mm)")
    if v_ident:
        head += ["after calibration (mm)", "σ after (mm)"]
    rows = []
    for n in names:
        v, s = _num(ident.get(n)), _num(errs.get(n))
        interval = (f"{_fmt(v - 3 * s, signed=True)} … {_fmt(v + 3 * s, signed=True)}"
                    if v is not None and s is not None else "—")
        row = [_param_html(n), _fmt(v, signed=True), _fmt(s), interval]
        if has_truth:
            row.append(_fmt(_truth(result, n), signed=True))
        if v_ident:
            row += [_fmt(v_ident.get(n), signed=True), _fmt(v_errs.get(n))]
        rows.append(row)
    return _table(head, rows)


def _correlation_table(result: Mapping[str, Any]) -> str:
    corr = _dict(result.get("correlation"))
    names, matrix = corr.get("names"), corr.get("matrix")
    if not isinstance(names, list) or not isinstance(matrix, list) or not names:
        return ""
    head = "".join(f"<th>{_param_html(str(n)) if str(n) in PARAM_NAMES else _e(n)}</th>"
                   for n in names)
    rows = []
    for i, n in enumerate(names):
        row = matrix[i] if i < len(matrix) and isinstance(matrix[i], list) else []
        cells = []
        for j in range(len(names)):
            r = _num(row[j]) if j < len(row) else None
            # Shade by |r|: strongly correlated pairs (|r| near 1) are the ones the
            # measurement cannot tell apart, and should jump out at the reader.
            shade = "" if r is None or i == j else (
                f' style="background:rgba(192,57,43,{min(abs(r), 1.0) * 0.55:.2f})"')
            # 0.9997 would print as "1.00", which reads as "identical" rather than
            # "almost inseparable"; give such values their digits.
            digits = 4 if r is not None and i != j and abs(r) >= 0.995 else 2
            cells.append(f'<td class="num"{shade}>{_fmt(r, digits)}</td>')
        label = _param_html(str(n)) if str(n) in PARAM_NAMES else _e(n)
        rows.append(f'<tr><th class="l">{label}</th>{"".join(cells)}</tr>')
    return (f'<h3>Correlation of the estimates</h3><table><thead><tr><th></th>{head}</tr>'
            f'</thead><tbody>{"".join(rows)}</tbody></table>'
            '<p class="small">Values near ±1 mean the measurement cannot separate the two '
            "parameters: an error in one is absorbed by the other.</p>")


def _deviations_table(result: Mapping[str, Any]) -> str:
    before = _dict(result.get("deviations"))
    after = _dict(_dict(result.get("verification")).get("deviations"))
    keys = _dev_keys(before, after)
    if not keys:
        return "<p>No deviations were measured.</p>"
    head = ["deviation", "measured (mm)", "std (mm)", "n", "model (mm)", "residual (mm)"]
    if after:
        head += ["after: measured (mm)", "after: std (mm)"]
    rows = []
    for k in keys:
        b, a = _dict(before.get(k)), _dict(after.get(k))
        m, f = _num(b.get("mean")), _num(b.get("model"))
        resid = m - f if m is not None and f is not None else None
        n = b.get("n")
        row = [_dev_html(k), _fmt(m, signed=True), _fmt(b.get("std")),
               _e(n) if isinstance(n, int) else "—", _fmt(f, signed=True),
               _fmt(resid, signed=True)]
        if after:
            row += [_fmt(a.get("mean"), signed=True), _fmt(a.get("std"))]
        rows.append(row)
    return _table(head, rows, caption=(
        "Π<sub>i</sub><sup>±</sup> along j: reading of the indicator touching leg i in "
        "direction j, in test posture Π<sub>i</sub><sup>±</sup>, minus its reading in "
        "Π<sub>0</sub>. std: spread over the measurement cycles; n: number of cycles."))


def _setups_table(result: Mapping[str, Any]) -> str:
    setups = result.get("setups")
    if not isinstance(setups, list) or not setups:
        return "<p>No setup was measured.</p>"
    rows = []
    for s in setups:
        s = _dict(s)
        inds = ", ".join(f"{_e(k)} → {_e(v)}" for k, v in _dict(s.get("indicators")).items())
        cu, cm = s.get("cycles_used"), s.get("cycles_max")
        cycles = f"{_e(cu)} of {_e(cm)}" if cm is not None else _e(cu if cu is not None else "—")
        flagged = s.get("flagged")
        rows.append([
            f"leg {_e(s.get('leg', '—'))}", inds or "—", cycles, _e(s.get("repeats", "—")),
            _fmt(s.get("spread_mm")),
            "<b>yes</b> — spread above the repeatability limit" if flagged else "no",
        ])
    return _table(["setup", "indicators (name → direction)", "cycles used", "repeats",
                   "spread (mm)", "flagged"], rows, left=2)


def _offsets_section(result: Mapping[str, Any]) -> str:
    before = _dict(result.get("offsets_before"))
    written = result.get("offsets_written")
    written = written if isinstance(written, dict) else {}
    wb = _dict(result.get("writeback"))
    out = []
    if wb:
        status = str(wb.get("status", "—"))
        cls = "box" if status == "written" else "box warn"
        text = _WRITEBACK_TEXT.get(status, status)
        reason = f"<br>Reason: {_e(wb['reason'])}" if wb.get("reason") else ""
        out.append(f'<div class="{cls}"><b>Write-back: {_e(status)}</b> — {_e(text)}.'
                   f"{reason}</div>")
    if before or written:
        rows = []
        for a in AXES:
            if a not in before and a not in written:
                continue
            b, w = _num(before.get(a)), _num(written.get(a))
            change = _fmt(w - b, signed=True) if b is not None and w is not None else "—"
            rows.append([f"axis {a}", _fmt(b, signed=True),
                         _fmt(w, signed=True) if written else "not written", change])
        out.append(_table(["axis", "offset before (mm)", "offset written (mm)", "change (mm)"],
                          rows, caption=(
            "The controller's joint zero offset o<sub>i</sub>; the correction is "
            "o<sub>i</sub> ← o<sub>i</sub> − Δρ<sub>i</sub>. The old values are saved in "
            "the run directory, so <code>orthocal rollback</code> can restore them.")))
    return "".join(out) or "<p>The controller's offsets were not read.</p>"


def _info_list(result: Mapping[str, Any]) -> str:
    machine = _dict(result.get("machine"))
    timing = _dict(result.get("timing"))
    rows = [
        ("run directory", f"<code>{_e(result.get('run_dir', '—'))}</code>"),
        ("started", _e(_when(result.get("started")))),
        ("finished", _e(_when(result.get("finished")))),
        ("duration", _e(_duration(result.get("duration_s", timing.get("wall_s"))))),
        ("machine", _e(
            f"leg length L = {_fmt(machine.get('leg_length'), 2)} mm, joint stroke "
            f"ρmin = {_fmt(machine.get('rho_min'), 1)} mm … ρmax = "
            f"{_fmt(machine.get('rho_max'), 1)} mm") if machine else "—"),
        ("model", _e(f"{_MODEL_TEXT.get(str(result.get('model')), result.get('model', '—'))}"
                     f" ({result.get('method', '—')})")),
    ]
    if result.get("simulated"):
        sim = _dict(result.get("simulation"))
        desc = "virtual machine (no hardware)"
        if sim:
            desc += (f"; seed {sim.get('seed') if sim.get('seed') is not None else 'random'}"
                     f", indicator noise σ = {_fmt(sim.get('noise_mm'), 4)} mm")
        rows.append(("simulation", _e(desc)))
    else:
        rows.append(("devices", "as configured in the station config (config.toml)"))
    if timing:
        rows.append(("timing", _e(
            f"wall {_duration(timing.get('wall_s'))}, {timing.get('moves', '—')} moves, "
            f"{timing.get('readings', '—')} readings, retries: {timing.get('retries', '—')}")))
    return '<dl class="kv">' + "".join(f"<dt>{_e(k)}</dt><dd>{v}</dd>" for k, v in rows) + "</dl>"


def _release_fonts() -> None:
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


def render_html(result: dict) -> str:
    """The whole report as one HTML string (no external resources)."""
    status = str(result.get("status", "unknown"))
    title = "Calibration report"
    when = _when(result.get("started"))
    try:
        plot_dev = _plot_deviations(result)
        plot_par = _plot_parameters(result)
    finally:
        if "matplotlib" in sys.modules:
            _release_fonts()
    figures = []
    if plot_dev:
        figures.append(
            f"<figure>{plot_dev}<figcaption>Figure 1. The 12 leg deviations: how far each "
            "indicator's reading in a test posture differs from its reading in "
            "Π<sub>0</sub>. Before calibration: measured (blue; error bar = std over the "
            "cycles, often smaller than the marker) and as the fitted model explains them "
            "(orange). After calibration: the verification measurement (green), which "
            "should be close to zero.</figcaption></figure>")
    if plot_par:
        figures.append(
            f"<figure>{plot_par}<figcaption>Figure 2. Identified parameters with ±1σ (thick) "
            "and ±3σ (thin) error bars; after calibration the re-identified values should be "
            "near zero. In a simulated run the red bar marks the value hidden in the virtual "
            "machine.</figcaption></figure>")
    status_cls = f"st-{status}" if status in _STATUS_TEXT else "st-failed"
    sim_tag = " (simulated)" if result.get("simulated") else ""
    badge = f'<span class="status {status_cls}">{_e(_STATUS_TEXT.get(status, status))}</span>'
    body = f"""
<h1>{_e(title)}{_e(sim_tag)}{badge}</h1>
<p class="meta">Orthoglide-type parallel machine · leg-parallelism calibration · {_e(when)}</p>
{_info_list(result)}
<h2>What was done</h2>
{_what_was_done(result)}
<h2>Result</h2>
{_result_paragraph(result)}
{_fit_box(result)}
{"".join(figures)}
<h2>Identified parameters</h2>
{_params_table(result)}
{_correlation_table(result)}
<h2>Deviations</h2>
{_deviations_table(result)}
<h2>Setups</h2>
{_setups_table(result)}
<h2>Controller offsets</h2>
{_offsets_section(result)}
<p class="small">Generated by orthocal. All lengths in millimetres.</p>
"""
    return (f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
            f'<meta name="viewport" content="width=device-width, initial-scale=1">'
            f"<title>{_e(title)} — {_e(when)}</title><style>{_CSS}</style></head>"
            f"<body>{body}</body></html>\n")


def write_html(result: dict, run_dir: Path) -> Path:
    """Write ``run_dir/report.html``: self-contained, plots inline as SVG."""
    path = Path(run_dir) / "report.html"
    _atomic_write(path, render_html(result))
    return path
