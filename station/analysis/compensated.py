"""What the geometry in the controller buys (docs/design.md, "The geometry in the
controller"): the run's ``accuracy.compensated``, the tool error with the
identified machine in the controller's kinematics (``orthocal export
--kinematics``) or in the program (``orthocal compensate``), beside the offsets
alone (``accuracy.after``).

The controller is told what ``station.record.identified`` reads from model.json:
Δρ now, and the tilts and gaps the kept model holds; every other parameter stays
nominal, and its value and uncertainty as the run pooled them are carried in the
prediction (orthocal.compensation.compensated_interval), so a tilt the model test
did not keep costs what it may be, not nothing.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from orthocal import GAP_NAMES, PARAM_NAMES, TILT_NAMES
from orthocal.compensation import compensated_interval
from station.analysis.accuracy_statement import (
    DRHO,
    LAYOUT_NAMES,
    Layout,
    Limits,
    covariance,
    grid,
    params,
)
from station.config import StationConfig
from station.record.result import Compensated
from station.record.result_accuracy import Accuracy, AfterInterval

#: How the identified machine reaches the controller, as the advice names them.
ROUTES_IN_FULL = [
    "LinuxCNC: orthocal export RUN_DIR --to linuxcnc --ini MACHINE.ini --kinematics "
    "--out DIR (the orthoglidekins component and its geometry)",
    "any controller with nominal kinematics: orthocal compensate PROGRAM --run RUN_DIR "
    "(the program's points moved)",
]


def told_names(layout: Layout | None, in_model: Sequence[str]) -> list[str]:
    """The parameters the controller is told: Δρ, and the tilts and gaps that both
    the kept model and the pooled layout hold (as station.record.identified reads
    model.json)."""
    held = () if layout is None else layout.names
    return [*DRHO, *(n for n in LAYOUT_NAMES if n in in_model and n in held)]


def nominal_reasons(layout: Layout | None, told: Sequence[str], model: str) -> dict[str, str]:
    """Each parameter left nominal, and why."""
    held = () if layout is None else layout.names
    out = {f"dL_{a}": "not identified beside the tilts and gaps from two stops per leg: "
                      "the leg's nominal length" for a in "xyz"}
    for name in (*TILT_NAMES, *GAP_NAMES):
        if name in told:
            continue
        out[name] = (f"not in the model the test kept ({model}): nominal (0); the run's "
                     "pooled value and its uncertainty are carried in the figure"
                     if name in held else "not identified by any round: nominal (0)")
    return out


def grouped(nominal: Mapping[str, str]) -> dict[str, list[str]]:
    """The parameters left nominal, by the reason given (one sentence each)."""
    out: dict[str, list[str]] = {}
    for name, why in nominal.items():
        out.setdefault(why, []).append(name)
    return out


def statement(points: np.ndarray, frame: str, *, drho_now: Mapping[str, float],
              cov: np.ndarray, wide: np.ndarray, dof: float | None,
              layout: Layout | None, in_model: Sequence[str], model: str,
              offsets_only: AfterInterval, form_words: str | None) -> Compensated:
    """``accuracy.compensated``: the tool error over ``points`` (the statement's
    grid, ``frame``) with the controller told ``told_names``. ``cov``: the 12×12
    statistical covariance of Δρ now and the pooled layout (station.analysis.accuracy_statement's);
    ``wide`` the same with what the legs' form may leave in the layout, for the
    intervals; ``offsets_only``: accuracy.after's figures."""
    lay = np.zeros(len(LAYOUT_NAMES)) if layout is None else layout.vector()
    estimate = params(drho_now, lay)
    told = told_names(layout, in_model)
    theta_c = np.array([v if n in told else 0.0 for n, v in
                        zip(PARAM_NAMES, estimate, strict=True)])
    # not told because the kept model holds them not: their pooled values are noise
    # about what may be nominal (Δρ is always told; ΔL has no variance)
    absent = [n not in told and n in LAYOUT_NAMES for n in PARAM_NAMES]
    iv = compensated_interval(theta_c, estimate, cov, dof, points, frame=frame,
                              systematic=wide - cov, absent=absent)
    nominal = nominal_reasons(layout, told, model)
    laid = [n for n in told if n not in DRHO]
    assumes = [
        "the controller is told Δρ as the last verification left it"
        + (f", and {', '.join(laid)} as the run identified them" if laid else ""),
        *(f"{', '.join(names)}: {why}" for why, names in grouped(nominal).items()
          if not names[0].startswith("dL")),
        "ΔL = 0 (leg lengths nominal; not identified beside the tilts and gaps from two "
        "stops per leg); a leg 0.1 mm long changes the field",
        "the figures are the mean and 95 % interval of what the identification's error "
        "leaves; " + (form_words.replace("the 95 % intervals of the after-figures",
                                         "they") if form_words
                      else "no systematic error is stated"),
        "orthocal compensate adds at most its --tolerance (default 1 µm) along the path",
    ]
    return Compensated(
        rms_mm=iv.rms_mm, max_mm=iv.max_mm, rms_interval_95_mm=iv.rms_interval_mm,
        max_interval_95_mm=iv.max_interval_mm,
        offsets_only_rms_mm=offsets_only.rms_mm,
        offsets_only_max_mm=offsets_only.max_mm, told=told, nominal=nominal,
        routes=list(ROUTES_IN_FULL), method=iv.method, assumes=assumes,
        field_rms_mm=[round(float(v), 7) for v in iv.point_rms_mm])



def of_run(config: StationConfig, limits: Limits | None, acc: Accuracy, *,
           drho_now: Mapping[str, float], drho_now_cov: np.ndarray | None, dof: float | None,
           layout: Layout | None, in_model: Sequence[str], model: str,
           form: tuple[np.ndarray, str] | None) -> Compensated:
    """:func:`statement` for a run, on the grid and frame of its statement ``acc``
    (station.analysis.accuracy_statement.statement's), as result.json holds it."""
    cov = covariance(drho_now_cov, layout)
    wide = cov if form is None else covariance(drho_now_cov, layout, form[0])
    return statement(grid(config, limits).points, acc.frame, drho_now=drho_now,
                     cov=cov, wide=wide, dof=dof, layout=layout, in_model=in_model,
                     model=model, offsets_only=acc.after,
                     form_words=None if form is None else form[1])
