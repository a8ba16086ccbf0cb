"""What a verification round says of the machine: a correction worth writing, the
machine shown converged, or neither (station.engine.closed_loop's verdicts), and in
words why a run that stopped undecided is not converged (docs/design.md, "Closed loop")."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from orthocal.loop import WRITABLE, shown_within, significant_corrections
from orthocal.numbers import finite


@dataclass(frozen=True)
class Verdict:
    verdict: str  # closed_loop.Verdict
    significant: list[str]  # the writable parameters beyond the noise of both rounds
    shown_mm: dict[str, float]  # per axis, how far the machine may be off at 95 %

    def fields(self) -> dict[str, Any]:
        """The round's entry in the result's ``iterations``."""
        return {"shown_within_95_mm": {k: finite(v) for k, v in self.shown_mm.items()},
                "verdict": self.verdict}


def converge_limit(converge_mm: float, offset_count_mm: float) -> float:
    """converge_mm plus half a count of the drive's offsets: "converged" claims each
    joint zero within this at 95 % (a correction is rounded to the count)."""
    return converge_mm + 0.5 * offset_count_mm


def judge(ident: Any, previous: Any | None, converge_mm: float, limit: float,
          target: dict[str, float] | None, passes_left: bool = False) -> Verdict:
    """The verdict on round ``ident`` (``previous``: the identification whose
    correction it verifies; None for the first measurement, judged against its
    own noise alone). Significant: beyond k standard errors of both rounds (of
    the first alone) and beyond converge_mm (orthocal.loop.significant_corrections);
    after a write-back, where the round cannot show the machine within ``limit`` and
    no further pass of it is left (``passes_left`` False), beyond the noise alone.
    Converged: every axis shown within ``limit`` at 95 % (orthocal.loop.shown_within):
    for a first measurement, a machine within tolerance that nothing is written
    to. Otherwise suspected (the 95 % interval excludes the aim on some axis) or
    unproven."""
    aim = target if previous else None
    beyond_noise = significant_corrections(
        ident.parameters, ident.std_errors, 0.0,
        previous_std_errors=previous.std_errors if previous else None,
        dof=ident.std_error_dof, previous_dof=previous.std_error_dof if previous else None,
        target=aim)
    sig = [n for n in beyond_noise
           if abs(ident.parameters[n] - (aim or {}).get(n, 0.0)) > converge_mm]
    shown = shown_within(ident.parameters, ident.std_errors, ident.std_error_dof,
                         target=target)
    if not sig and previous is not None and not passes_left and \
            any(v > limit for v in shown.values()):
        # converge_mm spares a correction too small to matter, where the machine can
        # be shown within it; where no further pass can show that, a correction beyond
        # the noise of both rounds is what stands between it and "converged": written.
        sig = beyond_noise
    verdict = "significant" if sig else "converged"
    if not sig and any(v > limit for v in shown.values()):
        seen = shown_within(ident.parameters, ident.std_errors, ident.std_error_dof,
                            target=target, sign=True)
        verdict = "suspected" if any(v > 0 for v in seen.values()) else "unproven"
    return Verdict(verdict, sig, shown)


def not_converged(entry: dict[str, Any], converge_mm: float, offset_count_mm: float) -> str:
    """Why the last verification (its ``iterations`` entry) could not show the machine
    converged, in words: how far the worst axis may still be off, and what to change."""
    shown = entry.get("shown_within_95_mm") or {}
    passes = len(entry.get("passes", [entry["phase"]]))
    worst = max(shown, key=lambda k: math.inf if shown[k] is None else shown[k])
    bound = shown[worst]
    how = "by an unknown amount (no standard error)" if bound is None else \
        f"by up to {1000 * bound:.1f} µm"
    ses = [v for k, v in entry["std_errors"].items() if k in WRITABLE and v is not None]
    noise = f" (standard error {1000 * max(ses):.1f} µm)" if ses else ""
    seen = "a correction is seen at 95 % but does not stand out of both rounds' noise" \
        if entry.get("verdict") == "suspected" else "no correction stands out of the noise"
    said = (f"after {passes} pass(es) of its last verification, Δρ_{worst[-1]} may still "
            f"be off {how} at 95 %, more than converge_mm = {1000 * converge_mm:g} µm + "
            f"half the drive's count ({500 * offset_count_mm:g} µm), and {seen}{noise}")
    if entry.get("fit_ok") is False:
        # the noise is not the cause: more of the same measurement cannot help
        return (f"{said}; the cause is the model, not the noise: model {entry.get('model')} "
                f"leaves {1000 * (entry.get('residual_rms_mm') or 0.0):.1f} µm RMS of "
                "residual against the scatter's "
                f"{1000 * (entry.get('noise_floor_mm') or 0.0):.1f} µm, so more cycles or "
                "quieter gauges will not help; look for what the model lacks (a loose "
                "gauge or stand, lost motion, legs bowed beyond [uncertainty] "
                "leg_straightness_mm) or name a larger model")
    return (f"{said}; measure with more cycles or readings, quieter gauges, or a larger "
            "converge_mm")
