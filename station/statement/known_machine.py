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
from orthocal.uncertainty import Uncertainty, combined, type_a
from station.analysis import accuracy_statement as accuracy
from station.analysis.run_budget import round_columns
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


def _moved(a: dict[str, float] | None, b: dict[str, float] | None) -> dict[str, float]:
    """Per Δρ name, b − a (writing the offsets o' for o moves Δρ by o' − o)."""
    if a is None or b is None:
        return dict.fromkeys(DRHO, 0.0)
    return {f"drho_{x}": float(b[x]) - float(a[x]) for x in AXES}


def _drho_uncertainty(rounds: Rounds, ident: Identification,
                      se: Mapping[str, float | None], tag: str) -> Uncertainty:
    """Δρ's: Type A the rounds joined (per axis), Type B the round's inputs."""
    held = [n for n in DRHO if n in ident.names]
    var = [float(se.get(n) or 0.0) ** 2 for n in held]
    part_a = type_a(held, np.diag(var), ident.std_error_dof)
    part_b = round_columns(rounds.config, ident, tag).pick(held)
    return combined([part_a, part_b], held)


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
    return values, combined([part_a, part_b], lay.names)


def _leg_lengths(rounds: Rounds, tag: str) -> tuple[dict[str, float], Uncertainty | None]:
    ident = rounds.last
    held = [n for n in DL if n in ident.names]
    if not held:
        return {}, None
    names = list(ident.names)
    idx = [names.index(n) for n in held]
    cov = np.asarray(ident.covariance, dtype=float)[np.ix_(idx, idx)]
    part_b = round_columns(rounds.config, ident, tag).pick(held)
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
                        drho=_drho_uncertainty(rounds, ident, se, tag), layout=layout,
                        layout_u=layout_u, dl=dl, dl_u=dl_u, apart=apart)


def layout_names() -> tuple[str, ...]:
    """The tilts and gaps, in PARAM_NAMES' order."""
    return accuracy.LAYOUT_NAMES
