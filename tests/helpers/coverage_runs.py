"""Whole runs of the engine on the Protocol-level fakes (tests/helpers/fakes.py) of
machines drawn at random, and their statements judged against the hidden machine
(docs/model.md, "The statement's uncertainty"): the coverage of the statement's 95 %
intervals over whole runs, shared by tests/station/statement/test_statement_coverage.py and
bench/statement_coverage.py.

Each machine's hidden errors are drawn within realistic ranges, and its stated inputs
are what it is drawn within:

- Δρ uniform in ±1 mm, tilts in ±0.3 mrad, gaps in ±0.2 mm, each joint's lost motion
  in 0–10 µm;
- the legs' form as the statement assumes it (orthocal.budget_columns, ALIKE): each
  gauge plane's sagitta s·(½·u₀ + ½·u_p), u₀ one draw for the machine, u_p one per
  plane, both uniform in ±1, s the stated straightness (:data:`STRAIGHTNESS_MM`);
- each gauge's scale error within its stated MPE (:data:`MPE_MM` over any travel the
  machines drawn give, :data:`TRAVEL_MM`), and each mounting's plunger off the leg's
  normal by an angle within the stated :data:`PLUNGER_DEG` (it reads cos θ of the
  travel);
- a temperature step within the stated ±:data:`TEMPERATURE_C` at a moment of the run
  drawn uniform: every leg grows by α·ΔT·L from then on (the machine after the run
  is the one at its reference temperature: the truth has no ΔL);
- stands placed by eye (±5 mm), 1 µm gauges.

What the fakes cannot simulate: a leg's form other than the bow 4h·t(1 − t) (a form
with more than one wave), a gauge error that is not a scale error (a periodic or
hysteresis error within the MPE), and a temperature that changes the machine's axes
as well as its legs."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from builders import FAST
from fakes import FakeRig, fake_config, run_on

from orthocal import AXES, GAP_NAMES, TILT_NAMES, Geometry
from orthocal.accuracy import error_field
from orthocal.budget import STEEL_ALPHA
from orthocal.budget_columns import ALIKE
from station.commands.simulate.launch import DEFAULT_MOUNT_ERROR_MM

#: The stated inputs ([uncertainty] and each gauge's mpe_mm), and what is drawn within.
STRAIGHTNESS_MM = 0.002
MPE_MM = 0.002
#: The largest travel of a gauge from its zero in these runs (deviations of Δρ of 1 mm,
#: tilts and gaps together stay below it): a scale error within ±MPE/TRAVEL keeps every
#: reading within the MPE.
TRAVEL_MM = 0.5
PLUNGER_DEG = 2.0
TEMPERATURE_C = 0.1
NOISE_MM = 0.001
#: Clock seconds of a run on the fakes (its moves at 1000 mm/s: 6–9 s): the temperature step
#: falls in [0, this].
RUN_CLOCK_S = 8.0

#: The kinds of quantity judged, by their names in the statement.
KINDS: dict[str, tuple[str, ...]] = {
    "drho as left": tuple(f"drho_{a}.as_left" for a in AXES),
    "tilts": TILT_NAMES,
    "gaps": GAP_NAMES,
    "tool after": ("tool.after.rms", "tool.after.max"),
}


@dataclass(frozen=True)
class Machine:
    """One drawn machine: its hidden errors, its gauges' and its temperature step."""

    seed: int
    drho: tuple[float, ...]
    tilt: tuple[float, ...]
    gap: tuple[float, ...]
    backlash: tuple[float, ...]
    plane_bow: tuple[float, ...]
    gauge_scale: tuple[float, ...]
    plunger_rad: tuple[float, ...]
    temperature_c: float
    step_at_s: float


def draw_machine(seed: int) -> Machine:
    """The machine of ``seed`` (module docstring)."""
    rng = np.random.default_rng([seed, 50])

    def u(lo: float, hi: float, n: int) -> tuple[float, ...]:
        return tuple(float(v) for v in rng.uniform(lo, hi, n))

    shared = float(rng.uniform(-1.0, 1.0))
    own = rng.uniform(-1.0, 1.0, 6)
    bow = STRAIGHTNESS_MM * (ALIKE * shared + (1.0 - ALIKE) * own)
    scale = MPE_MM / TRAVEL_MM
    return Machine(seed=seed, drho=u(-1.0, 1.0, 3), tilt=u(-0.3, 0.3, 3),
                   gap=u(-0.2, 0.2, 3), backlash=u(0.0, 0.010, 3),
                   plane_bow=tuple(float(b) for b in bow),
                   gauge_scale=u(-scale, scale, 2),
                   plunger_rad=u(-math.radians(PLUNGER_DEG), math.radians(PLUNGER_DEG), 64),
                   temperature_c=float(rng.uniform(-TEMPERATURE_C, TEMPERATURE_C)),
                   step_at_s=float(rng.uniform(0.0, RUN_CLOCK_S)))


def _rig(machine: Machine) -> FakeRig:
    """The fakes with ``machine``'s hidden errors, each mounting's plunger angle and the
    temperature step put in by wrapping the rig's hands and its axes' moves."""
    rig = FakeRig(seed=machine.seed, noise_mm=NOISE_MM, true_drho=machine.drho,
                  true_tilt=machine.tilt, true_gap=machine.gap, backlash=machine.backlash,
                  plane_bow=machine.plane_bow, gauge_scale=machine.gauge_scale,
                  mount_error_mm=DEFAULT_MOUNT_ERROR_MM)
    angles = iter(machine.plunger_rad)
    mount = rig.mount

    def mounted(name: str, leg: str, direction: str, at: float = 0.5) -> None:
        gauge = rig.gauges[name]
        # the scale error of the gauge, and the cosine of this mounting's plunger
        gauge.scale = (1.0 + machine.gauge_scale["AB".index(name)]) \
            * math.cos(next(angles)) - 1.0
        mount(name, leg, direction, at=at)

    rig.mount = mounted  # type: ignore[method-assign]
    move = rig.axes.move
    grown = STEEL_ALPHA * machine.temperature_c * rig.geometry.leg_length

    def moved(targets: Any, speed_mm_s: float | None = None) -> None:
        move(targets, speed_mm_s)
        if rig.clock.t >= machine.step_at_s:
            rig.machine.true_dl = np.full(3, grown)

    rig.axes.move = moved  # type: ignore[method-assign]
    return rig


def run_machine(machine: Machine, out: Path,
                procedure: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """A whole run on ``machine`` into ``out`` (the short procedure,
    builders.FAST, unless ``procedure``), stating its inputs; its result."""
    config = fake_config(uncertainty={"leg_straightness_mm": STRAIGHTNESS_MM,
                                      "temperature_change_c": TEMPERATURE_C,
                                      "plunger_angle_deg": PLUNGER_DEG},
                         **{**FAST, **(procedure or {})})
    indicators = [i.model_copy(update={"mpe_mm": MPE_MM}) for i in config.indicators]
    config = config.model_copy(update={"indicators": indicators})
    code, result = run_on(_rig(machine), out, config)
    assert code in (0, 3), result.get("message")
    return result


def truths(result: Mapping[str, Any], machine: Machine) -> dict[str, float]:
    """The hidden machine's value of each quantity :data:`KINDS` names: Δρ as the
    offsets written left it, the tilts and gaps, and the tool's RMS and max of |E|
    after the offsets, computed from the hidden machine over the grid the run stated
    its figures on (as tests/station/statement/test_tool_station.py does)."""
    o = np.array([result["offsets_final"][a] - result["offsets_before"][a] for a in AXES])
    out = {f"drho_{a}.as_left": machine.drho[i] + float(o[i]) for i, a in enumerate(AXES)}
    out.update(zip(TILT_NAMES, machine.tilt, strict=True))
    out.update(zip(GAP_NAMES, machine.gap, strict=True))
    acc = result["accuracy"]
    theta = np.array([*machine.drho, 0.0, 0.0, 0.0, *machine.tilt, *machine.gap])
    fld = error_field(np.asarray(acc["field"]["points_mm"]), Geometry(), theta, o,
                      acc["frame"])
    out["tool.after.rms"], out["tool.after.max"] = fld.rms_mm, fld.max_mm
    return out


@dataclass(frozen=True)
class Judged:
    """One quantity of one run: its truth, value and interval, and the error against
    the interval's half-width (|e|/U: inside where ≤ 1)."""

    seed: int
    name: str
    truth: float
    value: float
    interval: tuple[float, float]

    @property
    def inside(self) -> bool:
        return self.interval[0] <= self.truth <= self.interval[1]

    @property
    def ratio(self) -> float:
        """The truth's distance from the value over the interval's half-width on the
        truth's side."""
        lo, hi = self.interval
        half = (hi - self.value) if self.truth >= self.value else (self.value - lo)
        return abs(self.truth - self.value) / half if half > 0 else math.inf


def judge(result: Mapping[str, Any], machine: Machine) -> list[Judged]:
    """Every quantity of :data:`KINDS` the run states, against its truth (a quantity
    the statement lacks is missing from the list: the caller counts them)."""
    true = truths(result, machine)
    stated = {q["name"]: q for q in result.get("statement") or []}
    out = []
    for names in KINDS.values():
        for name in names:
            q = stated.get(name)
            if q is None or q.get("interval_95") is None:
                continue
            lo, hi = q["interval_95"]
            out.append(Judged(machine.seed, name, float(true[name]), float(q["value"]),
                              (float(lo), float(hi))))
    return out


def by_kind(judged: Sequence[Judged]) -> dict[str, list[Judged]]:
    return {kind: [j for j in judged if j.name in names] for kind, names in KINDS.items()}


def run_and_judge(seed: int, out: Path,
                  procedure: Mapping[str, Any] | None = None) -> list[Judged]:
    machine = draw_machine(seed)
    return judge(run_machine(machine, out, procedure), machine)


Runner = Callable[[int, Path], list[Judged]]
