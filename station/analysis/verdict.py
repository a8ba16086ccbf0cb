"""What a verification round says of the machine: a correction worth writing, the
machine shown converged, or neither (station.engine.closed_loop's verdicts), and in
words why a run that stopped undecided is not converged (docs/design.md, "Closed loop")."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from orthocal import Identification
from orthocal.geometry import AXES, Geometry
from orthocal.loop import (
    FALSE_ALARM,
    WRITABLE,
    joined_axis,
    shown_within,
    significant_corrections,
)
from orthocal.noise import coverage_factor
from orthocal.numbers import finite
from station.record.result import Ambiguity, Iteration
from station.record.result_base import Params


class JoinedRounds(NamedTuple):
    """A round's Δρ̂ joined with the rounds before it (:func:`joined_round`): the values,
    their standard errors, and per axis each round's weight in the value (round 0
    first), which the next round's covariance with it is summed over."""

    values: dict[str, float]
    std_errors: dict[str, float | None]
    weights: dict[str, tuple[float, ...]]


@dataclass(frozen=True)
class Judgement:
    verdict: str  # station.record.result.Verdict
    significant: list[str]  # the writable parameters beyond the noise of both rounds
    shown_mm: dict[str, float]  # per axis, how far the machine may be off at 95 %

    def shown(self) -> Params:
        """The round's ``shown_within_95_mm`` in the result's ``iterations``."""
        return {k: finite(v) for k, v in self.shown_mm.items()}


def _form_limits(se: float | None, floor: float | None, passes: tuple[int, int],
                 dof: float, limit: float) -> bool:
    """Whether the carried ``floor`` alone keeps an axis from being shown within
    ``limit``: were Δρ̂ at the aim, after all the passes left, k·√(floor² + (se² −
    floor²)·done/(done + left)) (the part above the floor averaged over the passes
    as independent data) would not be within it, and without the floor it would."""
    if se is None or floor is None or not math.isfinite(se):
        return False
    done, left = passes
    data = max(se**2 - floor**2, 0.0) * done / (done + left)
    k = coverage_factor(dof, 0.95)
    return k * math.sqrt(floor**2 + data) >= limit > k * math.sqrt(data)


def converge_limit(converge_mm: float, offset_count_mm: float) -> float:
    """converge_mm plus half a count of the drive's offsets: "converged" claims each
    joint zero within this at 95 % (a correction is rounded to the count)."""
    return converge_mm + 0.5 * offset_count_mm


def judge(ident: Identification, previous: Identification | None, limit: float,
          target: dict[str, float] | None, passes_left: bool = False,
          joined: JoinedRounds | None = None, floor: dict[str, float] | None = None,
          passes: tuple[int, int] = (1, 0),
          type_b: dict[str, float] | None = None) -> Judgement:
    """The verdict on round ``ident`` (``previous``: the identification whose
    correction it verifies; None for the first measurement, judged against its
    own noise alone). Significant: beyond k standard errors of both rounds (of
    the first alone) and beyond ``limit``, converge_mm with half a count of the
    drive's offsets (orthocal.loop.significant_corrections): a correction within
    half a count is none the drive can take, and one a little beyond it would leave
    the joint as far the other way;
    after a write-back, where the round cannot show the machine within ``limit``: on
    those axes, a leftover seen at 95 % (the rounds joined), and with no further pass
    of the round left (``passes_left`` False), any correction beyond the noise alone.
    Converged: every axis shown within ``limit`` at 95 % (orthocal.loop.shown_within):
    for a first measurement, a machine within tolerance that nothing is written
    to. Otherwise suspected (the 95 % interval excludes the aim on some axis) or
    unproven; ambiguous where an axis is out because another model explains the data
    as well (``ident.ambiguity_mm``, added to what the axis is shown within).
    ``joined``: the round's Δρ̂ and standard errors joined with the rounds before it
    (orthocal.loop.joined_with_previous): what the machine is shown within and seen
    off by; the corrections stand out of this round's own noise. ``floor``: the part
    of each Δρ standard error that further passes at the same stops cannot shrink
    (orthocal.carry.prior_floor), ``passes``: the round's passes so far and those left;
    form-limited where, with Δρ̂ at its aim, the passes left could not show an axis
    within ``limit`` for that part alone (:func:`_form_limits`). ``type_b``: each Δρ's
    Type B standard uncertainty (the stated inputs, station.analysis.run_budget.
    round_columns): what the machine is shown within carries it as the statement does
    (orthocal.loop.shown_within); budget-limited where it alone, the data perfect,
    keeps an axis from being shown within ``limit``."""
    aim = target if previous else None
    beyond_noise = significant_corrections(
        ident.parameters, ident.std_errors, 0.0,
        previous_std_errors=previous.std_errors if previous else None,
        dof=ident.std_error_dof, previous_dof=previous.std_error_dof if previous else None,
        target=aim)
    sig = [n for n in beyond_noise
           if abs(ident.parameters[n] - (aim or {}).get(n, 0.0)) > limit]
    values, ses = (joined[0], joined[1]) if joined else (ident.parameters, ident.std_errors)
    # what the data cannot decide (another model explaining them as well) is no
    # closer than it is, whatever the noise
    apart = ident.ambiguity_mm
    shown = {n: v + apart.get(n, 0.0)
             for n, v in shown_within(values, ses, ident.std_error_dof, target=target,
                                      type_b=type_b).items()}
    out = [n for n, v in shown.items() if v > limit]
    # the stated inputs alone (Type B, the same in every round) keep these out of the
    # limit however good the data: no pass can bring them in (a leftover the data see is
    # still written: it brings the machine closer, whatever can be shown of it)
    limited = [n for n in out if type_b and coverage_factor(None) * type_b.get(n, 0.0)
               + apart.get(n, 0.0) >= limit]
    seen = shown_within(values, ses, ident.std_error_dof, target=target, sign=True)
    if not sig and previous is not None and out:
        # the limit spares a correction too small to matter, where the machine can
        # be shown within it. Where it cannot, the next step mounts every setup either
        # way: a further pass of the same machine, or a write and its verification.
        # Where the leftover is seen at 95 %, the write is taken: it writes the rounds'
        # joined Δρ̂ (Flow.write), which leaves the least error that is known, and the
        # next verification joins on from there as a further pass would. With no pass
        # left, a correction beyond the noise of both rounds is written too.
        sig = [n for n in WRITABLE if (n in out and seen.get(n, 0.0) > 0.0)
               or (not passes_left and n in beyond_noise)]
    verdict = "significant" if sig else "converged"
    if not sig and out:
        verdict = "suspected" if any(v > 0 for v in seen.values()) else "unproven"
        if any(apart.get(n, 0.0) > 0.0 for n in out):
            verdict = "ambiguous"
        elif limited:
            verdict = "budget-limited"
        elif floor and any(_form_limits(ident.std_errors.get(n), floor.get(n), passes,
                                        ident.std_error_dof, limit) for n in out):
            verdict = "form-limited"
    return Judgement(verdict, sig, shown)


def joined_round(ident: Identification, before: JoinedRounds | None,
                 offsets_before: dict[str, float] | None,
                 offsets_written: dict[str, float] | None,
                 shared: Sequence[np.ndarray] = (), fresh: bool = False) -> JoinedRounds:
    """A round's Δρ̂ joined with ``before`` (the rounds before it, joined alike; None:
    the first round), moved by the offsets its write-back changed from
    ``offsets_before`` to ``offsets_written`` (read back; None: nothing written), per
    axis by orthocal.loop.joined_axis at the loop's false-alarm k. ``shared``: the
    round's Δρ̂ covariance (3 × 3) with each round before it, in order
    (orthocal.carry.cross_covariance: a prior it carried); their covariance with the
    joined value is that summed with the rounds' weights in it (GUM). Without: the
    rounds independent. ``fresh``: the rounds before are not joined (the round before
    lacks the axes' tilts this one holds: its Δρ̂ holds them, several µm off, an error
    no noise term of it covers)."""
    n = 0 if before is None else len(next(iter(before.weights.values()), ()))
    own = JoinedRounds(dict(ident.parameters), dict(ident.std_errors),
                 {name: (0.0,) * n + (1.0,) for name in WRITABLE if name in ident.parameters})
    if before is None or fresh:
        return own
    moved = {} if offsets_before is None or offsets_written is None else \
        {f"drho_{a}": offsets_written[a] - offsets_before[a] for a in AXES}
    k = coverage_factor(None, 1.0 - FALSE_ALARM)
    for i, name in enumerate(WRITABLE):
        if name not in own.values or name not in before.values:
            continue
        w = before.weights.get(name) or (0.0,) * (n - 1) + (1.0,)
        c = sum(wr * float(np.asarray(cov)[i, i]) for wr, cov in zip(w, shared, strict=False))
        both = joined_axis(own.values[name], finite(own.std_errors.get(name)),
                           before.values[name] + moved.get(name, 0.0),
                           finite(before.std_errors.get(name)), c, k)
        if both is None:
            continue
        own.values[name], own.std_errors[name], lam = both
        own.weights[name] = (*(lam * x for x in w), 1.0 - lam)
    return own


def stands_part(ident: Identification, geometry: Geometry) -> Params | None:
    """A round's entry ``stands_part_mm``: how much of each Δρ standard error the stands
    set by eye make (orthocal.design.drho_error_parts at the round's fit), where they
    were modelled (None: not modelled); read by :func:`not_converged`."""
    stands, sigma = ident.stand_model, ident.stand_sigma or 0.0
    if stands is None or not sigma > 0.0:
        return None
    from orthocal import design

    _, part = design.drho_error_parts(ident.keys, geometry, ident.model, ident.fit_vector,
                                      sigma, stands.prior_sd, stands)
    return {f"drho_{a}": float(v) for a, v in zip(AXES, part, strict=True)}


def annotate(entry: Iteration, ident: Identification, geometry: Geometry,
             floor: dict[str, float], type_b: dict[str, float] | None = None) -> None:
    """What a round's ``iterations`` entry says beside its verdict of what limits it:
    the stands' part of Δρ's error, another model that explains the data as well, the
    part the carried bows leave (``floor``, orthocal.carry.prior_floor) and the stated
    inputs' (``type_b``: their standard part of each Δρ's uncertainty)."""
    if type_b:
        entry.inputs_part_mm = {n: finite(v) for n, v in type_b.items() if n in WRITABLE}
    part = stands_part(ident, geometry)
    if part is not None:
        entry.stands_part_mm = part
    if ident.ambiguous_with is not None:
        entry.ambiguity = Ambiguity(explained_by=ident.ambiguous_with,
                                    apart_mm={**ident.ambiguity_mm})
    if floor:
        entry.form_floor_mm = {n: finite(v) for n, v in floor.items() if n in WRITABLE}


def _form_advice(worst: str, rounds: Sequence[Iteration]) -> str:
    """What would know the carried bows better: the round that measured them (the last
    one fitted with the bows and carrying none) says whether its error was the stands'
    set by eye, which only another mounting or a mark averages, or its gauges' noise,
    which more cycles average."""
    source = [r for r in rounds if r.model and r.model.endswith("+form")
              and r.form_floor_mm is None]
    part = (source[-1].stands_part_mm or {}).get(worst) if source else None
    se = source[-1].std_errors.get(worst) if source else None
    if part is not None and se and part > 0.5 * se:
        return (f"there the stands set by eye made {1000 * part:.1f} µm of Δρ_{worst[-1]}'s "
                f"{1000 * se:.1f} µm: to show the offsets converged, set the stands "
                "against a mark at each gauge plane and state [procedure] "
                "stand_tolerance_mm (more cycles cannot shrink that part)")
    return ("to show the offsets converged, read the second plane with more cycles "
            "([procedure] max_cycles_in_mounting) or quieter gauges")


def _or_inf(bound: float | None) -> float:
    return math.inf if bound is None else bound


def not_converged(entry: Iteration, converge_mm: float, offset_count_mm: float,
                  rounds: Sequence[Iteration] = ()) -> tuple[str, str]:
    """Why the last verification (its ``iterations`` entry; ``rounds``: every entry)
    could not show the machine converged, in words, as (why, remedy): how far the
    worst axis may still be off (the headline's, short), and what to change (the
    advice's)."""
    shown = entry.shown_within_95_mm or {}
    passes = len(entry.passes or [entry.phase])
    worst = max(shown, key=lambda k: _or_inf(shown[k]))
    bound = shown[worst]
    how = "by an unknown amount" if bound is None else f"by up to {1000 * bound:.1f} µm"
    limit = 1000 * converge_mm + 500 * offset_count_mm
    said = f"Δρ_{worst[-1]} may still be off {how} at 95 % (limit {limit:g} µm)"
    return said, _remedy(entry, worst, passes, rounds)


def _remedy(entry: Iteration, worst: str, passes: int, rounds: Sequence[Iteration]) -> str:
    """What would let the loop show the machine converged (:func:`not_converged`)."""
    after = f"after {passes} pass(es) of the last verification: "
    if entry.ambiguity is not None:
        apart = max(v or 0.0 for k, v in entry.ambiguity.apart_mm.items() if k in WRITABLE)
        return (f"{after}the axes' tilts ({entry.model}) and the legs' bows within the "
                f"stated straightness ({entry.ambiguity.explained_by}) explain the "
                f"deviations alike and put Δρ up to {2000 * apart:.1f} µm apart (what is "
                f"stated and written is their midpoint, within {1000 * apart:.1f} µm of "
                "either); no pass can decide it: read a second gauge plane ([[setups]] "
                "again with at = 0.75), or state the legs' measured straightness "
                "([uncertainty] leg_straightness_mm)")
    inputs = (entry.inputs_part_mm or {}).get(worst)
    se_worst = entry.std_errors.get(worst)
    if entry.verdict == "budget-limited" or (inputs is not None and se_worst is not None
                                             and inputs > se_worst):
        part = (entry.inputs_part_mm or {}).get(worst)
        size = f" ({1000 * part:.1f} µm standard)" if part is not None else ""
        return (f"{after}the stated inputs make most of Δρ_{worst[-1]}'s uncertainty{size}, "
                "and no pass shrinks them: measure and state them ([uncertainty], "
                "[[indicators]] mpe_mm; the budget names the largest)")
    floor = (entry.form_floor_mm or {}).get(worst)
    if entry.verdict == "form-limited" and floor is not None:
        return (f"{after}{1000 * floor:.1f} µm of Δρ_{worst[-1]}'s standard error comes "
                "from the legs' bows the pass with the second gauge plane measured, which "
                "no pass at the middles shrinks; " + _form_advice(worst, rounds))
    if entry.fit_ok is False:
        return (f"{after}model {entry.model} leaves "
                f"{1000 * (entry.residual_rms_mm or 0.0):.1f} µm RMS of residual against "
                f"the scatter's {1000 * (entry.noise_floor_mm or 0.0):.1f} µm: look for "
                "what the model lacks (a loose gauge or stand, lost motion, legs bowed "
                "beyond [uncertainty] leg_straightness_mm) or name a larger model")
    part = (entry.stands_part_mm or {}).get(worst)
    se = entry.std_errors.get(worst)
    if part is not None and se and part > 0.5 * se:
        return (f"{after}the stands set by eye make {1000 * part:.1f} µm of Δρ_{worst[-1]}'s "
                f"standard error {1000 * se:.1f} µm: more passes ([procedure] "
                "max_extra_passes) average it, and so do stands set against a mark with "
                "[procedure] stand_tolerance_mm stated")
    return (f"{after}measure with more cycles or readings, quieter gauges, or a larger "
            "converge_mm")
