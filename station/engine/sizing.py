"""How many cycles a mounting takes: the planned ones, and in a verification as many as
the verdict it must give needs, up to [procedure] max_cycles_in_mounting (docs/design.md,
"Closed loop"). A further pass of the first measurement ("m+1"…) is one: the first
pass found nothing to write, so the round must now show the machine converged."""

from __future__ import annotations

import math

import numpy as np

from drivers.base import OffsetResolution
from station.analysis.statistics import cycle_std_error
from station.analysis.verdict import converge_limit
from station.config import StationConfig
from station.plan.steps import Plan
from station.record.phase import Phase


class VerificationSizing:
    """The cycles of one mounting, decided from the cycles it has taken so far."""

    def __init__(self, config: StationConfig, plan: Plan, controller: OffsetResolution) -> None:
        self.config, self.plan, self.controller = config, plan, controller
        # The machine a verification expects, (model, 12-vector of its parameters): the
        # last round's fit, offsets at their aim after a write-back (set by the flow).
        self.expected: tuple[str, np.ndarray] | None = None
        self._target: float | None = None  # see verdict_se
        # The run's pass being measured (0-based; the sequencer sets it): its setups
        # are the plan's Plan.setups_of(pass_index).
        self.pass_index = 0

    def cycle_limit(self, phase: str) -> int:
        """Cycles a mounting may take in ``phase``: the planned ones, and in a
        verification (:func:`verifies`) up to [procedure] max_cycles_in_mounting."""
        proc = self.config.procedure
        if not verifies(phase):
            return proc.cycles
        most = proc.max_cycles_in_mounting or proc.cycles * (1 + proc.max_extra_passes)
        return max(proc.cycles, most)

    def decided(self, phase: str, cycles: list[dict[str, float]]) -> bool:
        """Whether this setup's cycles are enough for the verification's verdict: the
        standard error of its deviations' means (:func:`cycle_std_error`) at
        :meth:`verdict_se` or below. With the machine the verification expects known
        (:attr:`expected`), from the Δρ it will state: enough once that is within a
        third of the converge limit on every axis, or once the gauges' noise is no
        longer its larger part on any axis still short of it: the stands set by eye
        are the rest, and only another mounting averages them
        (orthocal.design.drho_error_parts). Every other phase: always."""
        if not verifies(phase):
            return True
        if self.plan.passes() is not None and self.pass_index == self.plan.two_plane_pass:
            # The one pass that reads the second gauge plane: every later pass carries
            # the bows it measures, whose noise only its cycles shrink (the later
            # passes' Δρ cannot be known better than they are): all its cycles.
            return False
        se = cycle_std_error(cycles)
        if self.expected is None or not math.isfinite(se) or se <= 0.0:
            # no scatter at all (quantised readings that never move): nothing to average
            return se <= self.verdict_se()
        from orthocal import FORM, design
        from station.analysis.model_choice import second_plane, with_form

        proc = self.config.procedure
        model, params = self.expected
        keys, _ = self.plan.deviation_keys(self.pass_index)
        # The pass that reads a second gauge plane measures the bows every later pass
        # carries (Plan.setups_of): sized for the bows' share of Δρ's error, so that
        # more cycles on its mountings, not more mountings, make it small; a pass at the
        # middles alone carries them, known.
        model = with_form(model, keys) if second_plane(keys) else model.removesuffix(FORM)
        noise, stands = design.drho_error_parts(
            keys, self.config.machine.geometry(), model, params, se,
            proc.stand_tolerance_mm / math.sqrt(3.0))
        short = np.hypot(noise, stands) > self._limit() / 3.0
        return bool(np.all(noise[short] <= stands[short]))

    def verdict_se(self) -> float:
        """The standard error of a deviation's mean at which a verification can show
        "converged": |Δρ̂| + k·se(Δρ) within converge_mm + half the drive's count,
        with |Δρ̂| ≈ se(Δρ) on a machine the last write fixed and k ≈ 2 (95 %), and
        se(Δρ) = G·se of the deviations, G the largest Δρ noise gain of the model on
        the plan's stops (orthocal.design.quality; auto: rho, the smallest model,
        whose verdict the loop's extra passes then extend)."""
        if self._target is None:
            from orthocal import design

            proc = self.config.procedure
            model = "rho" if proc.model == "auto" else proc.model
            # the stops of a pass at the legs' middles alone, where a second gauge
            # plane is read in one pass only (Plan.setups_of): the larger gain
            keys, _ = self.plan.deviation_keys(self.plan.two_plane_pass + 1)
            q = design.quality(keys, self.config.machine.geometry(), model)
            gain = max(v for n, v in q.noise_gain.items() if n.startswith("drho"))
            self._target = self._limit() / (3.0 * gain) if math.isfinite(gain) else 0.0
        return self._target

    def _limit(self) -> float:
        return converge_limit(self.config.procedure.converge_mm,
                              self.controller.offset_resolution_mm())


def verifies(phase: str) -> bool:
    """Whether a pass of ``phase`` must give a verification's verdict: every pass of a
    verification ("v", "v2+1"), and a further pass of the first measurement ("m+1"),
    taken because its first pass found no correction to write: the round must now
    show the machine within converge_mm. The first pass itself: a new mounting is
    what averages the stands' placement there, and its correction is usually large."""
    return Phase.parse(phase).sized_like_verification
