"""Closed-loop calibration maths: what a correction leaves behind, and when a
further correction is worth a round (docs/model.md, "Writing the offsets back" and
"Where the indicator plane is").

Only the joint offsets Δρ can be written to a controller. After o_i ← o_i − Δρ̂_i
the machine behaves as if its parameters were the identified ones with Δρ
zeroed: leg-length errors and axis tilts stay and still produce deviations.
A verification is judged against those predicted deviations, not against zero.
Where the offsets aim elsewhere than Δρ = 0 (``target``: the joint errors that
leave the least tool-point error on a machine with tilted axes, orthocal.accuracy),
the correction written is Δρ̂ − target and the machine behaves as if its Δρ were
the target. Works on parameter names, so it holds for any model (PARAM_NAMES).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np

from orthocal.geometry import AXES, Geometry, params_vector
from orthocal.measurement import Key, deviations
from orthocal.noise import coverage_factor
from orthocal.numbers import finite

#: The parameters a controller can correct: its zero offsets (o_i ← o_i − Δρ_i).
WRITABLE: tuple[str, ...] = tuple(f"drho_{a}" for a in AXES)


def after_correction(parameters: Mapping[str, float],
                     target: Mapping[str, float] | None = None) -> dict[str, float]:
    """The machine's parameters once the correction toward ``target`` is written
    back: the same parameters with every writable one at its target (default 0)."""
    aim = target or {}
    return {n: (float(aim.get(n, 0.0)) if n in WRITABLE else float(v))
            for n, v in parameters.items()}


def correction(parameters: Mapping[str, float],
               target: Mapping[str, float] | None = None) -> dict[str, float]:
    """What is written for the identified ``parameters``: Δρ̂ − target for each
    writable one (write-back sets o_i ← o_i − that)."""
    aim = target or {}
    return {n: float(v) - float(aim.get(n, 0.0)) for n, v in parameters.items()
            if n in WRITABLE}


def predicted_after_correction(keys: Sequence[Key], geometry: Geometry,
                               parameters: Mapping[str, float],
                               target: Mapping[str, float] | None = None) -> np.ndarray:
    """Exact deviations (model (1), :func:`orthocal.deviations`) that a verification
    should show after writing the correction of ``parameters`` toward ``target``:
    zero for a Δρ-only model aimed at Δρ = 0, the signature of ΔL, tilts and a
    non-zero target otherwise."""
    return deviations(keys, geometry, params_vector(after_correction(parameters, target)))


#: The loop's false-alarm rate per value: a machine the last round fixed is
#: rewritten in one run of a thousand (three axes). The normal's 3σ (0.27 % per
#: value) rewrote one run in 120 by design: at 20 runs, a 15 % chance that "every
#: run takes one write-back" fails (bench/loop_vs_noise.py saw it, 19/20).
FALSE_ALARM = 0.001 / 3


def significant_corrections(parameters: Mapping[str, float],
                            std_errors: Mapping[str, float | None],
                            converge_mm: float, k: float | None = None,
                            previous_std_errors: Mapping[str, float | None] | None = None,
                            dof: float | None = None, previous_dof: float | None = None,
                            target: Mapping[str, float] | None = None) -> list[str]:
    """Names of the writable parameters whose value is worth writing again: beyond
    ``k`` standard errors (not noise) AND beyond ``converge_mm`` (not too small to
    matter). A missing or infinite standard error never makes a value significant.

    After a write-back the verification sees what the previous correction left,
    which is that correction's own error even on a machine the model fully explains:
    under "the previous round fixed it", a re-identified Δρ_i is distributed with
    variance se_i² + se_prev,i². ``previous_std_errors`` (the identification that
    was written) adds that term, so a correction counts only when it is more than
    the noise of both measurements: writing less would trade one noise for another.
    The previous term is at most se_i: the same experiment with the same gauges has
    the same noise, and a larger se_prev comes from misfit (misplaced stands), the
    very bias the loop is there to remove.

    ``k`` None: the k at which a machine already fixed is rewritten with the
    probability :data:`FALSE_ALARM` per value, from Student's t on ``dof`` (and
    ``previous_dof``, combined by Welch–Satterthwaite): 3.59 for a noise known
    exactly, 3.86 for two rounds of the default three cycles (24 + 24 dof), 4.18
    for two rounds of two cycles. The bias the loop is for (misplaced stands: 10-50
    µm after one round) stands far beyond that. ``target``: the Δρ the offsets aim
    at (default 0): what counts is the distance from it.
    """
    out = []
    aim = target or {}
    for name in WRITABLE:
        if name not in parameters:
            continue
        value = abs(float(parameters[name]) - float(aim.get(name, 0.0)))
        se = finite(std_errors.get(name))
        if se is None:
            continue
        nu = dof
        if previous_std_errors is not None:
            prev = finite(previous_std_errors.get(name))
            if prev is None:
                continue
            # A written round no noisier than this one: its leftover is a fair trade
            # of noises (hypot). A noisier one (a verification joined with the layout
            # the rounds before measured): its leftover is an error this round resolves,
            # and the term fades as se²/se_prev, continuous at se_prev = se.
            prev = prev if prev <= se else se * se / prev
            nu = _welch(se, dof, prev, previous_dof)
            se = math.hypot(se, prev)
        kk = k if k is not None else coverage_factor(nu, 1.0 - FALSE_ALARM)
        if value > kk * se and value > converge_mm:
            out.append(name)
    return out


def shown_within(parameters: Mapping[str, float], std_errors: Mapping[str, float | None],
                 dof: float | None, target: Mapping[str, float] | None = None,
                 level: float = 0.95, sign: bool = False,
                 type_b: Mapping[str, float] | None = None) -> dict[str, float]:
    """Per writable parameter, how far from ``target`` (default 0) the machine's Δρ can
    be at ``level`` (two-sided): |Δρ̂ − target| + k·se, k from Student's t on ``dof``
    (the normal's without). A missing or infinite standard error bounds nothing
    (inf). ``sign``: instead, how far it is at least, |Δρ̂ − target| − k·se (> 0:
    the interval excludes the target, a correction seen at that level; −inf
    without a standard error). The closed loop says "converged" only where every bound is within
    converge_mm and half the drive's count (a correction is rounded to it, so no
    offset can be set closer): the promise the word makes (docs/design.md, "Closed
    loop"). The verification measures the machine as the drive holds its offsets,
    rounded, so the rounding is inside the bound. ``type_b``: each parameter's Type B
    standard uncertainty (the stated inputs, systematic: the same in every round),
    combined with the standard error as the GUM does (quadrature, Welch–Satterthwaite
    dof with Type B at ∞: orthocal.uncertainty), so that what the loop calls
    converged is what the statement states."""
    aim = target or {}
    out = {}
    for name in WRITABLE:
        if name not in parameters:
            continue
        se = finite(std_errors.get(name))
        value = abs(float(parameters[name]) - float(aim.get(name, 0.0)))
        if se is None:
            out[name] = -math.inf if sign else math.inf
            continue
        ub = float((type_b or {}).get(name, 0.0))
        # Welch–Satterthwaite with the Type B part at ∞ dof (GUM G.4.1)
        nu = None if dof is None or se <= 0.0 else (se * se + ub * ub) ** 2 / (se**4 / dof)
        half = coverage_factor(nu, level) * math.hypot(se, ub)
        out[name] = value - half if sign else value + half
    return out


def joined_axis(value: float, se: float | None, previous: float, previous_se: float | None,
                covariance: float, k: float) -> tuple[float, float, float] | None:
    """One axis of a round's Δρ̂ (``value``, ``se``) joined with what the rounds before
    said of the same joint (``previous``, already moved by the offsets written since,
    ``previous_se``), the two sharing ``covariance`` (mm²: what a carried prior makes
    them share, docs/model.md (14); 0 for independent rounds): the GUM combination
    (1 − λ)·a + λ·b with the least variance,

        λ = (se² − c) / (se² + se_p² − 2c),  clipped to [0, 1],
        u² = (1 − λ)²·se² + λ²·se_p² + 2·λ·(1 − λ)·c

    (inverse variance where c = 0). Returns (value, standard error, λ), or None where
    either has no standard error, or the two disagree beyond ``k`` standard errors of
    their difference, √(se² + se_p² − 2c): the write did not move the joint as written,
    or a round's model is wrong, and the round alone is what the machine shows."""
    if se is None or previous_se is None or se <= 0 or previous_se <= 0:
        return None
    c = float(np.clip(covariance, -se * previous_se, se * previous_se))
    spread = se**2 + previous_se**2 - 2.0 * c
    if spread <= 0.0:  # one and the same measurement: nothing to join
        return None
    if abs(value - previous) > k * math.sqrt(spread):
        return None
    lam = min(max((se**2 - c) / spread, 0.0), 1.0)
    var = (1 - lam) ** 2 * se**2 + lam**2 * previous_se**2 + 2 * lam * (1 - lam) * c
    return (1 - lam) * value + lam * previous, math.sqrt(max(var, 0.0)), lam


def joined_with_previous(values: Mapping[str, float], std_errors: Mapping[str, float | None],
                         previous: Mapping[str, float], previous_std_errors:
                         Mapping[str, float | None], moved: Mapping[str, float],
                         k: float, covariance: Mapping[str, float] | None = None
                         ) -> tuple[dict[str, float], dict[str, float | None]]:
    """A verification's Δρ̂ joined with what the round before it knew of the same
    joints: that round's Δρ̂ moved by the offsets written since (``moved``, mm per
    writable name: the write-back read back, o_new − o_old, which moves Δρ by as
    much), per axis by :func:`joined_axis`: by inverse variance, se² = 1/(1/se² +
    1/se_prev²), where the two are independent; with ``covariance`` (mm² per name:
    what the two share, a prior the round carried) the GUM combination with it. An
    axis whose two disagree beyond ``k`` standard errors of their difference is not
    joined: the verification alone is what the machine shows. An axis without a
    standard error in either: this one's."""
    out_v: dict[str, float] = {}
    out_se: dict[str, float | None] = {}
    for name in WRITABLE:
        if name not in values:
            continue
        v, se = float(values[name]), finite(std_errors.get(name))
        out_v[name], out_se[name] = v, se
        if name not in previous:
            continue
        p = float(previous[name]) + float(moved.get(name, 0.0))
        both = joined_axis(v, se, p, finite(previous_std_errors.get(name)),
                           float((covariance or {}).get(name, 0.0)), k)
        if both is not None:
            out_v[name], out_se[name] = both[0], both[1]
    return out_v, out_se


def _welch(a: float, nu_a: float | None, b: float, nu_b: float | None) -> float | None:
    """Welch–Satterthwaite dof of a² + b² (None: a term's dof unknown, the normal)."""
    if nu_a is None or nu_b is None:
        return None
    den = (a**4 / nu_a if a else 0.0) + (b**4 / nu_b if b else 0.0)
    return (a * a + b * b) ** 2 / den if den > 0 else None


