"""The machine as the run knows it (:class:`KnownMachine`): each parameter's value at
the start of the run and now, and one joint distribution of their errors
(orthocal.uncertainty): the Type A part of each fit (Δρ: the rounds joined; the
layout: pooled over the rounds) and the Type B inputs through each fit's own
sensitivity, one input where two fits see the same (the legs' form).

Δρ at the start and Δρ now differ by the offsets written, which were read back and
are known exactly: the two carry the same uncertainty (docs/model.md, "The
statement's uncertainty")."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from orthocal import AXES, PARAM_NAMES, Identification
from orthocal.uncertainty import Uncertainty, combined, type_a, type_b
from station.analysis import accuracy_statement as accuracy
from station.analysis.joints import LeadInputs, lead_inputs
from station.analysis.run_budget import lead_columns, round_columns
from station.statement.snapshot import Rounds

DRHO: tuple[str, ...] = tuple(f"drho_{a}" for a in AXES)
DL: tuple[str, ...] = tuple(f"dL_{a}" for a in AXES)


@dataclass(frozen=True)
class KnownMachine:
    """``start``: Δρ at the start of the run; ``now``: Δρ as the offsets written left
    it (measured, or where nothing was measured after the last write, its aim);
    ``aim``: what the offsets aim at; ``drho``: their one uncertainty (over DRHO);
    ``layout``: the pooled tilts and gaps (mrad, mm) and ``layout_u`` theirs;
    ``dl``: leg lengths where the last round's model held them, ``dl_u`` theirs;
    ``apart``: per parameter, how far another explanation the data cannot rule out
    puts it (the legs' bows where the fit has tilts; model.md "Tilts or bows")."""

    start: dict[str, float]
    now: dict[str, float]
    aim: dict[str, float]
    measured_now: bool
    drho: Uncertainty
    layout: dict[str, float]
    layout_u: Uncertainty | None
    dl: dict[str, float]
    dl_u: Uncertainty | None
    apart: dict[str, float]

    def params(self, which: str = "now") -> np.ndarray:
        """The 12-vector of PARAM_NAMES: Δρ (``which``: "now" or "start"), ΔL where
        identified (else 0), the layout (0 where not held)."""
        drho = self.now if which == "now" else self.start
        values = {**drho, **self.dl, **self.layout}
        return np.array([float(values.get(n, 0.0)) for n in PARAM_NAMES])

    def joint(self) -> Uncertainty:
        """The errors of all twelve parameters together (one input where two fits see
        the same one)."""
        parts = [self.drho] + [u for u in (self.layout_u, self.dl_u) if u is not None]
        return combined(parts, PARAM_NAMES)


def _offsets_at(rounds: Rounds, n: int) -> dict[str, float] | None:
    """The offsets the controller held when round ``n`` (0-based) was measured: before
    the run, or as the write-back before it left them (read back)."""
    if rounds.offsets_before is None:
        return None
    held = dict(rounds.offsets_before)
    for w in rounds.writes[:n]:
        if w.written is not None:
            held = dict(w.written)
    return held


def offsets_moved(rounds: Rounds) -> dict[str, float]:
    """How far the offsets the run leaves lie from those it started with, per axis (mm):
    where on its screw a joint commanded ρ now stands, beside where the joints were
    tested (the run's start)."""
    moved = _moved(None if rounds.offsets_before is None else dict(rounds.offsets_before),
                   _offsets_at(rounds, len(rounds.writes)))
    return {d[-1]: v for d, v in moved.items()}


def _moved(a: dict[str, float] | None, b: dict[str, float] | None) -> dict[str, float]:
    """Per Δρ name, b − a (writing the offsets o' for o moves Δρ by o' − o)."""
    if a is None or b is None:
        return dict.fromkeys(DRHO, 0.0)
    return {f"drho_{x}": float(b[x]) - float(a[x]) for x in AXES}


def _joined_leads(names: list[str], parts: list[tuple[Uncertainty, np.ndarray]]
                  ) -> Uncertainty:
    """The joints' leads over ``names`` of a value joined from several estimates, each
    estimate's lead columns over ``names`` weighted by W (``parts``): Σ W·c. A lead is
    one input in every round, so it passes whole through the joining (docs/model.md,
    "The identification with joint tables"); none without parts."""
    if not parts:
        return type_b(names, np.zeros((len(names), 0)), [], [])
    total = sum((W @ u.columns for u, W in parts), np.zeros_like(parts[0][0].columns))
    return type_b(names, total, parts[0][0].labels, parts[0][0].sources)


def _pool_leads(rounds: Rounds, layouts: list[accuracy.RoundLayout], names: tuple[str, ...],
                leads: LeadInputs) -> list[tuple[Uncertainty, np.ndarray]]:
    """The lead columns of a pooled layout's rounds over ``names``, each with its pooling
    weight Σ_p·Σ_r⁻¹ (accuracy_statement.pool_layout), from the fit each came from."""
    pool = accuracy.pool_layout(layouts)
    if pool is None or pool.names != names:
        return []
    out = []
    for r in layouts:
        source = rounds.layout_fits.get(r.phase)
        if r.phase in pool.rounds and r.names == names and source is not None \
                and all(n in source.names for n in names):
            out.append((lead_columns(rounds.config, source, leads).pick(list(names)),
                        pool.covariance @ np.linalg.inv(r.covariance)))
    return out


def _round_leads(rounds: Rounds, r: int, leads: LeadInputs) -> Uncertainty:
    """Round ``r``'s estimate's lead columns over its names: its own data's (K·(J4)),
    and where it carried the layout the earlier rounds pooled, that prior's through
    its gain (orthocal.carry: the prior holds the same leads)."""
    fit = rounds.idents[r]
    own = lead_columns(rounds.config, fit, leads)
    if fit.prior_gain is None:
        return own
    earlier = {it.phase for it in rounds.iterations[:r]}
    layouts = [lay for lay in rounds.layout_rounds if lay.phase in earlier]
    pool = accuracy.pool_layout(layouts)
    if pool is None:
        return own
    parts = _pool_leads(rounds, layouts, pool.names, leads)
    if not parts:
        return own
    prior = _joined_leads(list(pool.names), parts)
    embedded = np.zeros_like(own.columns)
    for i, n in enumerate(pool.names):
        if n in fit.names:
            embedded[list(fit.names).index(n)] = prior.columns[i]
    return type_b(fit.names, own.columns + np.asarray(fit.prior_gain) @ embedded,
                  own.labels, own.sources)


def _drho_uncertainty(rounds: Rounds, ident: Identification, n: int,
                      se: Mapping[str, float | None], tag: str) -> Uncertainty:
    """Δρ's: Type A the rounds joined (per axis), Type B the round's inputs and the
    joints' leads through each round joined (its weights)."""
    held = [n for n in DRHO if n in ident.names]
    var = [float(se.get(n) or 0.0) ** 2 for n in held]
    part_a = type_a(held, np.diag(var), ident.std_error_dof)
    part_b = round_columns(rounds.config, ident, tag).pick(held)
    leads = lead_inputs(rounds.joints)
    weights = rounds.joined[n].weights if n < len(rounds.joined) else {}
    parts = []
    for r, fit in enumerate(rounds.idents[:n + 1] if leads else ()):
        # each axis' weight of round r in the joined value (its own alone where unjoined)
        w = [(weights.get(d) or (0.0,) * n + (1.0,))[r] for d in held]
        if any(w) and all(d in fit.names for d in held):
            parts.append((_round_leads(rounds, r, leads).pick(held), np.diag(w)))
    return combined([part_a, part_b, _joined_leads(held, parts)], held)


def _layout(rounds: Rounds) -> tuple[dict[str, float], Uncertainty | None]:
    lay, fit = rounds.layout, rounds.layout_fit
    if lay is None:
        return {}, None
    values = {n: float(v) for n, v in zip(lay.names, lay.values, strict=True)}
    part_a = type_a(lay.names, lay.covariance, lay.dof)
    if fit is None or lay.rounds is None:
        return values, part_a
    held = [n for n in lay.names if n in fit.names]
    part_b = round_columns(rounds.config, fit, lay.rounds[-1]).pick(held)
    # the pooled layout is Σ W_r·ℓ_r, W_r = Σ_p·Σ_r⁻¹ (accuracy_statement.pool_layout)
    leads = lead_inputs(rounds.joints)
    parts = _pool_leads(rounds, list(rounds.layout_rounds), lay.names, leads) if leads else []
    return values, combined([part_a, part_b, _joined_leads(list(lay.names), parts)],
                            lay.names)


def _leg_lengths(rounds: Rounds, tag: str) -> tuple[dict[str, float], Uncertainty | None]:
    ident = rounds.last
    held = [n for n in DL if n in ident.names]
    if not held:
        return {}, None
    names = list(ident.names)
    idx = [names.index(n) for n in held]
    cov = np.asarray(ident.covariance, dtype=float)[np.ix_(idx, idx)]
    part_b = round_columns(rounds.config, ident, tag, lead_inputs(rounds.joints)).pick(held)
    return ({n: float(ident.parameters[n]) for n in held},
            combined([type_a(held, cov, ident.std_error_dof), part_b], held))


def known_machine(rounds: Rounds) -> KnownMachine:
    """The machine of a run that identified Δρ (its last round's): values and their
    one joint uncertainty."""
    n = len(rounds.idents) - 1
    ident = rounds.last
    if n < len(rounds.joined):
        values, se = rounds.joined[n].values, rounds.joined[n].std_errors
    else:
        values, se = dict(ident.parameters), dict(ident.std_errors)
    at_n = _offsets_at(rounds, n)
    now_offsets = _offsets_at(rounds, len(rounds.writes))
    shift_now = _moved(at_n, now_offsets)
    shift_start = _moved(at_n, None if rounds.offsets_before is None
                         else dict(rounds.offsets_before))
    held = [d for d in DRHO if d in values]
    measured = rounds.verified
    aim = {d: float(rounds.target.get(d, 0.0)) for d in DRHO}
    now = {d: float(values[d]) + shift_now[d] for d in held} if measured else \
        {d: aim[d] for d in held}
    start = {d: float(values[d]) + shift_start[d] for d in held}
    tag = rounds.iterations[n].phase if n < len(rounds.iterations) else "m"
    layout, layout_u = _layout(rounds)
    dl, dl_u = _leg_lengths(rounds, tag)
    last = rounds.iterations[-1] if rounds.iterations else None
    apart = {} if last is None or last.ambiguity is None else \
        {k: float(v) for k, v in last.ambiguity.apart_mm.items() if v is not None}
    return KnownMachine(start=start, now=now, aim=aim, measured_now=measured,
                        drho=_drho_uncertainty(rounds, ident, n, se, tag), layout=layout,
                        layout_u=layout_u, dl=dl, dl_u=dl_u, apart=apart)


def layout_names() -> tuple[str, ...]:
    """The tilts and gaps, in PARAM_NAMES' order."""
    return accuracy.LAYOUT_NAMES
