"""``orthocal identify READINGS.csv``: identification alone, from a CSV of deviations.

READINGS.csv (docs/design.md): header ``posture,leg,direction,deviation_mm``, one row
per deviation, posture ``+``/``-``, leg and direction ``x``/``y``/``z``
(direction ≠ leg). An intermediate stop Π_i(s) (``[procedure] strokes``) is a
posture written as its signed stroke in mm, ``+30`` or ``-50.5``: the same
string as in the run's deviation keys ("+30xy"), so no extra column is needed;
``+``/``-`` remain ρmax/ρmin of the geometry options.

An optional ``cycle`` column lets a deviation appear once per cycle (repeats);
without it a repeated (posture, leg, direction) is an error, because
it is far more often a copy-paste slip than a deliberate repeat.

``--model auto`` needs the noise of the measurement: the cycle-to-cycle scatter
of a CSV with a cycle column (one row per deviation and cycle); a CSV with one value
per deviation carries none, and auto is refused for it.

A CSV carries no stand positions: where it has the cycle scatter, the indicator
stands are modelled as placed within ±``--mount-error`` mm of the legs' middles
(default 5, what a run assumes of stands placed by eye; orthocal.stands), so
that auto never takes for a tilt or a gap what misplaced stands can make.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
from pathlib import Path

from orthocal import Geometry, Identification, IdentificationError, identify, select_model
from orthocal.budget import combine, propagation, stands_source
from orthocal.noise import coverage_factor, noise_from_cycles
from orthocal.numbers import finite
from orthocal.postures import check_posture, stroke
from orthocal.stands import Stands, describe_stands
from station.errors import BadInput, read_input

REQUIRED = ("posture", "leg", "direction", "deviation_mm")
OPTIONAL = ("cycle",)
Key = tuple[str, str, str]


def read_deviations(path: Path, geometry: Geometry | None = None) -> dict[Key, list[float]]:
    """Parse READINGS.csv; every problem is a BadInput naming the file and line.
    With ``geometry``, a stroke posture must also lie within ±leg_length."""
    text = read_input(path, encoding="utf-8-sig")  # a spreadsheet's BOM is not a column
    rows = csv.reader(text.splitlines())
    columns = _read_header(path, next(rows, None))
    col = {c: columns.index(c) for c in columns}

    data: dict[Key, list[float]] = {}
    seen: dict[tuple, int] = {}
    for lineno, row in enumerate(rows, start=2):
        if not row or all(not cell.strip() for cell in row):
            continue
        if len(row) != len(columns):
            raise BadInput(f"{path}: line {lineno}: {len(row)} fields, expected {len(columns)}")
        cell = {c: row[i].strip() for c, i in col.items()}
        where = f"{path}: line {lineno}"
        key, value_mm = _parse_row(where, cell, geometry)
        ident = (*key, cell.get("cycle", ""))
        if ident in seen:
            sign, leg, direction = key
            what = f"cycle {ident[3]!r} of " if ident[3] else ""
            raise BadInput(
                f"{where}: duplicate row: {what}posture {sign} leg {leg} "
                f"direction {direction} already on line {seen[ident]}"
                + ("" if ident[3] else " (add a 'cycle' column for repeats)")
            )
        seen[ident] = lineno
        data.setdefault(key, []).append(value_mm)
    if not data:
        raise BadInput(f"{path}: no data rows after the header")
    return data


def _read_header(path: Path, header: list[str] | None) -> list[str]:
    """The header's column names, lower-cased; a BadInput on line 1 unless it holds
    every required column, nothing unknown and nothing twice."""
    if not header or not any(h.strip() for h in header):
        raise BadInput(f"{path}: line 1: empty file, expected header {','.join(REQUIRED)}")
    columns = [h.strip().lower() for h in header]
    missing = [c for c in REQUIRED if c not in columns]
    if missing:
        raise BadInput(f"{path}: line 1: missing column(s) {', '.join(missing)}")
    unknown = [c for c in columns if c not in REQUIRED + OPTIONAL]
    if unknown:
        raise BadInput(f"{path}: line 1: unknown column(s) {', '.join(unknown)}")
    if len(set(columns)) != len(columns):
        raise BadInput(f"{path}: line 1: a column appears twice")
    return columns


def _parse_row(where: str, cell: dict[str, str], geometry: Geometry | None
               ) -> tuple[Key, float]:
    """One data row's (posture, leg, direction) and deviation in mm; a BadInput
    prefixed with ``where`` (file and line) for the first field that is wrong."""
    sign, leg, direction = cell["posture"], cell["leg"].lower(), cell["direction"].lower()
    try:
        check_posture(sign)
        if geometry is not None:
            stroke(sign, geometry)
    except ValueError:
        raise BadInput(
            f"{where}: posture must be + or - or a signed nonzero stroke "
            f"in mm within ±leg_length such as +30, got {sign!r}") from None
    for field, value in (("leg", leg), ("direction", direction)):
        if value not in ("x", "y", "z"):
            raise BadInput(f"{where}: {field} must be x, y or z, got {value!r}")
    if leg == direction:
        raise BadInput(f"{where}: direction must differ from leg ({leg!r})")
    try:
        value_mm = float(cell["deviation_mm"])
    except ValueError:
        raise BadInput(
            f"{where}: deviation_mm is not a number: {cell['deviation_mm']!r}") from None
    if not math.isfinite(value_mm):
        raise BadInput(f"{where}: deviation_mm must be finite, got {value_mm}")
    return (sign, leg, direction), value_mm


def format_table(result: Identification, geometry: Geometry,
                 stated: dict | None = None) -> str:
    """Human-readable result: each parameter with its 95 % expanded uncertainty
    (``stated``: :func:`uncertainty`; None: none can be stated), k and dof said once,
    the fit, and the per-deviation table."""
    width = max(10, *(len(f"Π_{k[1]}({k[0]}) {k[2]}") for k in result.keys))
    lines = [
        f"Identification: model {result.model}, method {result.method}, "
        f"{len(result.keys)} deviations (L = {geometry.leg_length:g}, "
        f"strokes rho_min = {geometry.rho_min:g}, rho_max = {geometry.rho_max:g} mm)",
        "",
        f"  {'parameter':<10} {'value':>10} {'± (95 %)':>10}",
    ]
    expanded = (stated or {}).get("expanded", {})
    for name in result.names:
        u = expanded.get(name)
        u_text = f"{u:10.4f}" if u is not None and math.isfinite(u) else f"{'n/a':>10}"
        unit = "mrad" if name.startswith("tilt_") else "mm"
        lines.append(f"  {name:<10} {result.parameters[name]:10.4f} {u_text} {unit}")
    lines += ["", f"  {_coverage_line(stated)}"]
    sigma = f"{result.sigma:.4f} mm" if math.isfinite(result.sigma) else "n/a (no redundancy)"
    lines += [
        "",
        f"  residual RMS {result.residual_rms:.4f} mm, σ̂ {sigma}, "
        f"condition number {result.condition_number:.2f}",
        "",
        f"  {'deviation':<{width}} {'measured':>10} {'model':>10} {'residual':>10}",
    ]
    for key, value, res in zip(result.keys, result.values, result.residuals, strict=True):
        sign, _, plane = key[0].partition("@")
        posture = f"^{sign}" if sign in ("+", "-") else f"({sign})"
        label = f"Π_{key[1]}{posture} {key[2]}" + (f" @{plane}" if plane else "")
        lines.append(f"  {label:<{width}} {value:10.4f} {value - res:10.4f} {res:10.4f}")
    return "\n".join(lines)


def _coverage_line(stated: dict | None) -> str:
    """k and the degrees of freedom of every ± above, said once."""
    if stated is None:
        return ("no ± can be stated: as many parameters as deviations leave no residual "
                "to estimate the noise from, and there is no cycle column")
    dof = stated["dof"]
    on = "infinite degrees of freedom (the normal's)" if dof is None else \
        f"{dof:.1f} degrees of freedom"
    extra = f"; Type B: {', '.join(stated['type_b'])}" if stated["type_b"] else ""
    return (f"each ± is the 95 % expanded uncertainty U = k·u, k = {stated['k']:.2f} "
            f"(Student's t on {on}; Type A: {stated['type_a']}{extra})")


def has_noise(data: dict[Key, list[float]]) -> bool:
    """Whether the CSV carries a noise estimate: repeats (a cycle column) that scatter."""
    if not any(len(v) >= 2 for v in data.values()):
        return False
    return noise_from_cycles(data)[0] > 0


def uncertainty(result: Identification, geometry: Geometry, data: dict[Key, list[float]],
                mount_error: float) -> dict | None:
    """The 95 % intervals the identification can state (GUM: u_c of Type A and Type B
    parts, k from Student's t on the effective dof, one k for every parameter: the
    largest). With a noise estimate (a cycle column whose repeats scatter), the fit's
    standard errors on the noise's dof, the stands modelled in the fit. Without one, the
    fit's standard errors from its residual (K − p dof), which misplaced stands bias
    rather than scatter, and the stands set within ±``mount_error`` of the legs'
    middles carried as a Type B term (orthocal.budget.stands_source). None where no
    standard error exists (no residual: as many parameters as deviations)."""
    se = {n: float(result.std_errors[n]) for n in result.names}
    noise = has_noise(data)
    dof = result.std_error_dof if noise else float(result.dof)
    if not (dof > 0 and all(math.isfinite(v) for v in se.values())):
        return None
    sources = [] if noise or mount_error == 0.0 else \
        [stands_source(propagation(result, geometry), mount_error)]
    budget = combine(se, dof, sources)
    dofs = [v for v in budget["effective_dof"].values() if v is not None]
    nu = min(dofs) if dofs else None
    k = coverage_factor(nu)
    standard = {n: float(budget["combined_mm"][n]) for n in result.names}
    expanded = {n: k * u for n, u in standard.items()}
    type_b = [] if not sources else \
        [f"indicator stands within ±{mount_error:g} mm of the legs' middles (--mount-error)"]
    return {"level": 0.95, "k": k, "dof": nu, "standard": standard, "expanded": expanded,
            "interval_95": {n: [result.parameters[n] - u, result.parameters[n] + u]
                            for n, u in expanded.items()},
            "type_a": ("the cycle-to-cycle scatter" if noise
                       else "the fit's own residual, no cycle column"),
            "type_b": type_b}


def not_known(data: dict[Key, list[float]], mount_error: float) -> list[str]:
    """What a CSV without a noise estimate cannot tell, in words (empty where it has one)."""
    if has_noise(data):
        return []
    stands = (f"their placement within ±{mount_error:g} mm of the legs' middles "
              "(--mount-error) is carried in every ± as a Type B term instead"
              if mount_error > 0 else "they are taken exactly at the legs' middles "
              "(--mount-error 0)")
    return ["without a cycle column (repeats that scatter) there is no noise estimate: the "
            "σ̂ above is the fit's residual, misfit and noise alike",
            "so no model test (--model auto needs the noise) and no prior weight for the "
            f"indicator stands: {stands}"]


def _stands(args: argparse.Namespace, data: dict[Key, list[float]]) -> Stands | None:
    """The stands to model: a CSV says nothing of where they stood, so each is taken
    within ±--mount-error of the leg's middle (None: 0, placed exactly; or one value
    per deviation, or repeats without scatter: no noise to weigh their prior against)."""
    mount_error = args.mount_error
    if not (math.isfinite(mount_error) and 0.0 <= mount_error <= 50.0):
        raise BadInput(f"--mount-error must lie in [0, 50] mm, got {mount_error:g}")
    if mount_error == 0.0 or not any(len(v) >= 2 for v in data.values()):
        return None
    if not noise_from_cycles(data)[0] > 0:  # repeats copied: no scatter to weigh with
        return None
    return Stands(tolerance=mount_error)


def main(args: argparse.Namespace) -> int:
    try:
        geometry = Geometry(leg_length=args.leg_length, rho_min=args.rho_min, rho_max=args.rho_max)
    except ValueError as exc:
        raise BadInput(f"geometry: {exc}") from None
    data = read_deviations(Path(args.csv), geometry)
    stands = _stands(args, data)
    selection = None
    try:
        if args.model == "auto":
            if not any(len(v) >= 2 for v in data.values()):
                raise BadInput(
                    f"{args.csv}: --model auto needs the noise of the measurement, and one "
                    "value per deviation carries none: give a CSV with a cycle column (one row "
                    "per deviation and cycle) or name a model")
            # the stands modelled: a gap or tilt that stands placed within ±--mount-error
            # could leave is not taken for geometry (orthocal.selection)
            selection = select_model(data, geometry, method=args.method, stands=stands)
            result = selection.identification
        else:
            result = identify(data, geometry, model=args.model, method=args.method,
                              stands=stands)
    except IdentificationError as exc:
        raise BadInput(f"{args.csv}: {exc}") from None
    stated = uncertainty(result, geometry, data, args.mount_error)
    unknown = not_known(data, args.mount_error)
    if args.json:
        doc = result.to_dict()
        if selection is not None:
            doc["model_selection"] = selection.to_dict()
        doc["uncertainty_95"] = None if stated is None else {
            **{k: v for k, v in stated.items() if k not in ("standard", "expanded",
                                                             "interval_95", "dof")},
            "dof": finite(stated["dof"]),
            "standard": {n: finite(v) for n, v in stated["standard"].items()},
            "expanded": {n: finite(v) for n, v in stated["expanded"].items()},
            "interval_95": {n: [finite(a), finite(b)]
                            for n, (a, b) in stated["interval_95"].items()}}
        doc["not_known"] = unknown
        print(json.dumps(doc, indent=2))
    else:
        print(format_table(result, geometry, stated))
        if selection is not None:
            print(f"\n  model chosen by auto: {selection.reason}")
        if unknown:
            print("\n" + "\n".join(f"  {line}" for line in unknown))
        elif selection is None or stands is None:  # auto's reason names modelled stands
            print(f"\n  {_stands_note(args.mount_error, stands, result)}")
    return 0


def _stands_note(mount_error: float, stands: Stands | None, result: Identification) -> str:
    """One line on the indicator stands: modelled (and what came out), or why not."""
    if stands is not None:
        return describe_stands(result.stands, stands)
    if mount_error == 0.0:
        return "indicator stands taken exactly at the legs' middles (--mount-error 0)"
    return (f"indicator stands not modelled: these values carry no noise (cycle "
            f"scatter) to weigh them against, so tilts and gaps here may be stands placed up to "
            f"±{mount_error:g} mm off the legs' middles (--mount-error)")
