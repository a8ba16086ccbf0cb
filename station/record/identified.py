"""The machine a run identified, as a controller's kinematics take it (docs/design.md,
"The geometry in the controller"): one value per kinematic parameter, in
orthoglidekins' pins and units, each with its 95 % interval and, where the run
did not identify it, why it is left at its nominal value.

Read from a finished run's result.json and model.json. What the controller is
told (``theta_c``, orthocal/compensation.py) holds, per parameter:

- Δρ: what the offsets the run wrote did not correct (``drho_now``, the statement's
  ``drho_*.as_left``);
- a tilt or a gap: the pooled value where the model the run kept holds it; else
  nominal (0), the run's value and interval named in the note: the model test
  found it within the noise, so the controller is not told noise;
- ΔL: where the kept model identified it; else nominal (L), named.

Each value's 95 % interval and its note's figure are the run's statement's (docs/design.md,
"The statement of the machine"), the one uncertainty every view prints; a record from
before the statement keeps model.json's standard errors times k (legacy).

Refused, in one line: a run that failed or was aborted, or that identified
nothing (no model.json). Whether a run that completed may be put into a controller
as it stands (converged, its last round not ambiguous) is the caller's to ask, of
station.record.exportable: an export may be forced, ``orthocal compensate`` may not.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, ValidationError

import orthocal
from orthocal import AXES, MODELS, PARAM_NAMES
from station.record.io import UnreadableResult, read_result
from station.record.model import MachineModel
from station.record.quantity_text import plus_minus
from station.record.result import RunResult
from station.record.result_base import JsonObject
from station.record.result_statement import Quantity

#: orthoglidekins' pins in PARAM_NAMES order (docs/design.md, "The geometry in the
#: controller"): leg-length-i is L + ΔL_i, the others the parameters themselves.
PINS: dict[str, str] = {
    **{f"drho_{a}": f"drho-{a}" for a in AXES},
    **{f"dL_{a}": f"leg-length-{a}" for a in AXES},
    "tilt_yx": "tilt-yx", "tilt_zx": "tilt-zx", "tilt_zy": "tilt-zy",
    "gap_xy": "gap-xy", "gap_xz": "gap-xz", "gap_yz": "gap-yz",
}
#: The component's name: its pins are orthoglidekins.<pin>.
COMPONENT = "orthoglidekins"


class NotACalibration(ValueError):
    """A run directory that holds no identified machine, in one line naming the file."""


class _Frozen(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class GeometryValue(_Frozen):
    """One kinematic parameter as the controller is told it."""

    name: str
    pin: str
    unit: Literal["mm", "mrad"]
    value: float
    nominal: float
    identified: bool
    interval_95: tuple[float, float] | None
    note: str


class IdentifiedMachine(_Frozen):
    """The machine a run identified, for a controller's kinematics or ``orthocal
    compensate``. ``values`` in PARAM_NAMES order; ``estimate`` the run's best
    value of every parameter (a pooled tilt the model test did not keep included),
    ``theta_c`` what the controller is told."""

    run_dir: str
    machine_id: str | None
    model: str
    leg_length: float
    rho_min: float
    rho_max: float
    offsets_held_by: Literal["controller", "station"] | None
    values: tuple[GeometryValue, ...]
    estimate: tuple[float, ...]

    @property
    def geometry(self) -> orthocal.Geometry:
        return orthocal.Geometry(self.leg_length, self.rho_min, self.rho_max)

    def theta_c(self) -> np.ndarray:
        """The 12-vector of PARAM_NAMES the controller is told (ΔL, not L + ΔL)."""
        return np.array([v.value - (self.leg_length if v.name.startswith("dL") else 0.0)
                         for v in self.values])

    def nominal(self) -> list[GeometryValue]:
        """The parameters left at their nominal values."""
        return [v for v in self.values if not v.identified]

    def describe(self) -> str:
        """The run, the machine and the model, in one line (file headers)."""
        return (f"run {self.run_dir}, machine {self.machine_id or 'without [machine] id'}, "
                f"model {self.model}")


def _read(path: Path, what: str) -> JsonObject:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise NotACalibration(f"{path}: no {what}") from None
    except OSError as exc:
        raise NotACalibration(f"{path}: cannot read ({exc.strerror})") from None
    except ValueError as exc:
        raise NotACalibration(f"{path}: not a {what} ({exc})") from None
    if not isinstance(data, dict):
        raise NotACalibration(f"{path}: not a {what}")
    return data


def identified_machine(run_dir: str | Path) -> IdentifiedMachine:
    """The machine the run in ``run_dir`` identified; NotACalibration (one line) for a run
    that failed, was aborted or identified nothing (station.record.exportable says
    whether one that completed is a calibration to trust)."""
    run = Path(run_dir)
    try:
        result = read_result(run / "result.json")
    except UnreadableResult as exc:
        raise NotACalibration(str(exc)) from None
    status = result.status
    if status in ("failed", "aborted"):
        raise NotACalibration(f"{run}: the run {status} ({result.message or 'no message'})"
                              ": it is no calibration to put into a controller")
    if not (run / "model.json").exists():
        raise NotACalibration(f"{run}: the run identified nothing (no model.json)")
    try:
        model = MachineModel.model_validate(_read(run / "model.json", "machine model"))
    except ValidationError as exc:
        first = exc.errors()[0]
        where = ".".join(str(p) for p in first["loc"])
        raise NotACalibration(f"{run / 'model.json'}: {where}: {first['msg']}") from None
    return _machine(run, result, model)


def _machine(run: Path, result: RunResult, model: MachineModel) -> IdentifiedMachine:
    kept = model.model
    if kept not in MODELS:
        raise NotACalibration(f"{run / 'model.json'}: model {kept!r} is not one of orthocal's")
    columns = {c for c in MODELS[kept] if c < len(PARAM_NAMES)}
    # the record's model types these as open maps: a name missing is one line here,
    # not a KeyError further down
    for field, names in (("parameters", PARAM_NAMES),
                         ("drho_now", [n for n in PARAM_NAMES if n.startswith("drho")])):
        missing = [n for n in names if n not in getattr(model, field)]
        if missing:
            raise NotACalibration(f"{run / 'model.json'}: {field}: no {', '.join(missing)}")
    q = {x.name: x for x in result.statement or []}
    values = []
    for c, name in enumerate(PARAM_NAMES):
        kind = name.split("_")[0]
        told = c in columns and name in model.estimated
        said = q.get(f"{name}.as_left" if kind == "drho" else
                     f"dl_{name[-1]}" if kind == "dL" else name)
        if said is not None and said.value is not None:
            values.append(_stated(name, kind, model, told, said))
        elif kind == "drho":
            values.append(_legacy_drho(name, model, result))
        else:
            values.append(_layout_value(name, kind, model, told,
                                        orthocal.coverage_factor(model.std_errors_dof)))
    estimate = [model.drho_now[n] if n.startswith("drho") else model.parameters[n]
                for n in PARAM_NAMES]
    return IdentifiedMachine.model_validate(dict(
        run_dir=result.run_dir or str(run), machine_id=result.machine.id, model=kept,
        leg_length=model.geometry.leg_length_mm, rho_min=model.geometry.rho_min_mm,
        rho_max=model.geometry.rho_max_mm, offsets_held_by=result.offsets_held_by,
        values=tuple(values), estimate=tuple(float(v) for v in estimate)))


#: What a Δρ pin carries, in its note.
DRHO_NOTE = "the joint's error the offsets written left (last verification)"


def _whether_it_holds(iv: tuple[float, float] | None, base: float) -> str:
    """Whether the interval of a value the controller is not told holds its nominal
    value, in words: the interval is the run's estimate's, not the nominal value's, so
    a note never claims "within its noise" for an estimate whose interval excludes it."""
    if iv is None or iv[0] <= base <= iv[1]:
        return "its interval holds the nominal value"
    return ("its interval does not hold the nominal value, but the model test over the "
            "whole run did not keep it")


def _stated(name: str, kind: str, model: MachineModel, told: bool,
            q: Quantity) -> GeometryValue:
    """A parameter the run's statement states (docs/design.md, "The statement of the
    machine"): Δρ as left, a tilt, a gap, ΔL; its value and its 95 % interval are the
    statement's, the note its text (station.record.quantity_text). Told where the model
    the run kept holds it (Δρ always), else nominal with the statement's value named."""
    base = model.geometry.leg_length_mm if kind == "dL" else 0.0
    unit: Literal["mm", "mrad"] = "mrad" if kind == "tilt" else "mm"
    iv = None if q.interval_95 is None else (base + q.interval_95[0], base + q.interval_95[1])
    value = float(q.value)  # type: ignore[arg-type]  # the caller checked it
    if kind == "drho" or told:
        note = DRHO_NOTE if kind == "drho" else f"identified (model {model.model})"
        return GeometryValue(name=name, pin=PINS[name], unit=unit, value=base + value,
                             nominal=base, identified=True, interval_95=iv,
                             note=f"{note}; the run's statement: {plus_minus(q)} (95 %)")
    where = _whether_it_holds(iv, base)
    return GeometryValue(name=name, pin=PINS[name], unit=unit, value=base, nominal=base,
                         identified=False, interval_95=iv,
                         note=f"nominal: the model test kept {model.model!r}, which holds no "
                              f"{name}; the run's statement is {plus_minus(q)} (95 %; "
                              f"{where}), carried in accuracy.compensated's interval")


def _legacy_drho(name: str, model: MachineModel, result: RunResult) -> GeometryValue:
    """Δρ now of a record from before the statement: model.json's, with k × the last
    verification's standard error."""
    value = model.drho_now[name]
    rem = result.remaining
    se = rem.std_errors.get(name) if rem is not None else None
    k = orthocal.coverage_factor(rem.std_errors_dof if rem else None)
    iv = None if se is None or not math.isfinite(se) else (value - k * se, value + k * se)
    return GeometryValue(name=name, pin=PINS[name], unit="mm", value=float(value),
                         nominal=0.0, identified=True, interval_95=iv, note=DRHO_NOTE)


def _layout_value(name: str, kind: str, model: MachineModel, told: bool,
                  k: float) -> GeometryValue:
    """ΔL (as the leg's length L + ΔL), a tilt or a gap the statement does not state (a
    record from before it, a ΔL not identified): model.json's value where the model it
    kept holds it, else nominal with its value and why in the note."""
    base = model.geometry.leg_length_mm if kind == "dL" else 0.0
    value = float(model.parameters[name])
    se = model.std_errors.get(name)
    iv = None if se is None else (base + value - k * se, base + value + k * se)
    unit: Literal["mm", "mrad"] = "mrad" if kind == "tilt" else "mm"
    if told:
        return GeometryValue(name=name, pin=PINS[name], unit=unit, value=base + value,
                             nominal=base, identified=True, interval_95=iv,
                             note=f"identified (model {model.model})")
    if se is None:
        why = (f"not identified: {model.not_estimated[name]}" if name in model.not_estimated
               else f"not in model {model.model}")
        return GeometryValue(name=name, pin=PINS[name], unit=unit, value=base, nominal=base,
                             identified=False, interval_95=None, note=why)
    shown = f"{base + value:+.4f} {unit} [{iv[0]:+.4f}, {iv[1]:+.4f}] (95 %)" if iv else ""
    where = _whether_it_holds(iv, base)
    return GeometryValue(name=name, pin=PINS[name], unit=unit, value=base, nominal=base,
                         identified=False, interval_95=iv,
                         note=f"nominal: the model test kept {model.model!r}, which holds no "
                              f"{name}; the run's estimate is {shown} ({where}), carried in "
                              "accuracy.compensated's interval")
