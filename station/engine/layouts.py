"""What no offset changes, kept round by round (docs/design.md, "Closed loop"): the
axes' layout (tilts, gaps) each round measured, the legs' bows where a second gauge
plane was read, and the fits they came from; a later round joins them
(orthocal.carry), and so shares their error: how much, round by round, for the
joining of the rounds (docs/model.md, "Rounds that carry an earlier round")."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

import orthocal
from orthocal import Identification, carry, design
from orthocal.geometry import BOW_NAMES, TILT_NAMES, Geometry
from orthocal.selection import LEVEL
from station.analysis import accuracy_statement as accuracy
from station.analysis.model_choice import carried_form, second_plane, with_tilts
from station.analysis.statistics import Measurement
from station.config import StationConfig
from station.errors import RunFailed

#: A source of a carried prior: (the round's phase, what of it: "layout", "form", or
#: "whole" where a fit was carried whole).
SourceKey = tuple[str, str]


@dataclass(frozen=True)
class Source:
    """A fit an earlier round made of what no offset changes: its names, their
    covariance, and the fit itself (two sources from one fit share its covariance)."""

    names: tuple[str, ...]
    covariance: np.ndarray
    fit: Identification


class Layouts:
    """The rounds' layouts and bows; ``identify`` fits a measurement with a named
    model (the run's model choice, station.analysis.model_choice)."""

    def __init__(self, geometry: Geometry,
                 identify: Callable[[Measurement, str], Identification]) -> None:
        self.geometry, self.identify = geometry, identify
        # each round's rho+tilt fit, for the tilts the run states (engine.accuracy)
        self.layout_rounds: list[accuracy.RoundLayout] = []
        # Each round's fit of the legs' bows (a second gauge plane): no offset
        # changes them either, so later rounds join them as they join the layout.
        self.form_rounds: list[accuracy.RoundLayout] = []
        # The fit each round's layout came from: what the legs' form may leave in the
        # layout (one gauge plane per leg) is read off it once, for the tool's
        # intervals (orthocal.budget.form_covariance).
        self.layout_fits: dict[str, Identification] = {}
        # What the rounds carried, and from which fits: their shared error (shared)
        self.sources: dict[SourceKey, Source] = {}
        self.priors: dict[str, carry.CarriedPrior] = {}

    def add(self, phase: str, m: Measurement, ident: Identification) -> None:
        """The round's axes layout (tilts and gaps): from its own fit if it has them
        all, else from a rho+tilt+gap fit of the same measurement (what the run could
        not rule out; rho+tilt where the gaps cannot be told); a round measured again
        replaces what its earlier passes gave."""
        self.layout_rounds = [t for t in self.layout_rounds if t.phase != phase]
        self.form_rounds = [t for t in self.form_rounds if t.phase != phase]
        self.sources = {k: s for k, s in self.sources.items() if k[0] != phase}
        form = accuracy.round_form(phase, ident)
        if form is not None:
            if second_plane(ident.keys):
                # The tilts of a round at the legs' middles alone hold the bows (a uniform
                # bow is a tilt there): the round that read both planes replaces them.
                fitted = {t.phase for t in self.form_rounds} | {phase}
                self.layout_rounds = [t for t in self.layout_rounds if t.phase in fitted]
            self.form_rounds.append(form)
            self.sources[(phase, "form")] = Source(form.names, form.covariance, ident)
        layout, source = accuracy.round_layout(phase, ident), ident
        whole = layout is not None and len(layout.names) == len(accuracy.LAYOUT_NAMES)
        for model in () if whole or not len(m.deviations) else accuracy.LAYOUT_MODELS:
            try:
                fit = self.identify(m, model)
            except RunFailed:
                continue  # too little data for this layout: try the smaller one
            if (found := accuracy.round_layout(phase, fit)) is not None:
                layout, source = found, fit
            break
        if layout is not None:
            self.layout_rounds.append(layout)
            self.layout_fits[phase] = source
            self.sources[(phase, "layout")] = Source(layout.names, layout.covariance, source)

    def pooled_tilts(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The rounds' pooled tilts (mrad, TILT_NAMES order) and their covariance
        (accuracy_statement.pool_layout, which leaves out a round whose layout disagrees
        with the others'); None where they hold none."""
        pooled = accuracy.pool_layout(self.layout_rounds)
        if pooled is None or not set(TILT_NAMES) <= set(pooled.names):
            return None
        idx = [pooled.names.index(n) for n in TILT_NAMES]
        return pooled.values[idx], pooled.covariance[np.ix_(idx, idx)]

    def tilts_shown(self, m: Measurement, straightness: Mapping[tuple[str, str], float]
                    ) -> bool:
        """Whether the pooled tilts (:meth:`pooled_tilts`) are the axes': the three stand
        out of their noise (their χ² beyond the model test's LEVEL), and one stands beyond
        what the legs bowed within ``straightness`` make of a tilt on ``m``'s stops
        (orthocal.design.bow_tilts; at the middles a uniform bow is a tilt) by more than
        k standard errors (two-sided, LEVEL)."""
        from scipy.special import chdtrc, ndtri  # the χ² upper tail, the normal quantile

        found = self.pooled_tilts()
        if found is None:
            return False
        t, cov = found
        try:
            chi2 = float(t @ np.linalg.solve(cov, t))
        except np.linalg.LinAlgError:
            return False
        bows = design.bow_tilts(list(m.for_identify()), self.geometry, straightness)
        k = float(ndtri(1.0 - LEVEL / 2))
        se = np.sqrt(np.maximum(np.diag(cov), 0.0))
        return float(chdtrc(len(t), chi2)) < LEVEL and bool(np.any(np.abs(t) > bows + k * se))

    def with_shown_tilts(self, phase: str, m: Measurement, ident: Identification,
                         straightness: Mapping[tuple[str, str], float]) -> Identification:
        """A verification's model (``ident``, chosen by auto from its own data) with the
        axes' tilts where the rounds so far, this one's layout fit among them, show
        them (:meth:`tilts_shown`): one round against its stands set by eye may not
        single out 0.05 mrad, and a model without the tilts puts them in its Δρ̂
        (several µm at a standard error under one). With the tilts, the rounds' pooled
        layout is joined (:meth:`carried`), so Δρ̂ pays little noise for them. A round
        left between the tilts and the legs' bows (model_choice.ambiguous) keeps the
        tilts alone: bows within the stated ``straightness`` cannot make them. The
        round's layout is then its own fit's. Otherwise ``ident`` as it is (the bows'
        fits, which hold no tilts at the middles, too)."""
        between = ident.ambiguous_with is not None
        if not between and ("tilt" in ident.model.split("+")
                            or ident.model.endswith(orthocal.FORM)):
            return ident
        if not self.tilts_shown(m, straightness):
            return ident
        try:
            tilted = self.identify(m, with_tilts(ident.model))
        except RunFailed:
            return ident
        self.add(phase, m, tilted)
        return tilted

    def form_fit(self, phase: str) -> Identification | None:
        """The layout fit of the latest round before ``phase``'s that fitted the legs'
        bows (a second gauge plane), or None."""
        fits = [fit for p, fit in self.layout_fits.items()
                if p != phase and all(b in fit.names for b in BOW_NAMES)]
        return fits[-1] if fits else None

    def carry_form(self, phase: str, config: StationConfig,
                   m: Measurement) -> Identification | None:
        """A pass at the legs' middles after the round that read a second gauge plane,
        joined with that round's widest layout fit, bows and all
        (model_choice.carried_form); None where that does not apply."""
        self.priors.pop(phase, None)
        first = self.form_fit(phase)
        ident = carried_form(config, m, first) if first is not None else None
        if ident is None or first is None:
            return ident
        source_phase = next(p for p, fit in self.layout_fits.items() if fit is first)
        names = tuple(n for n in first.names if not n.startswith("drho_"))
        idx = [first.names.index(n) for n in names]
        cov = np.asarray(first.covariance)[np.ix_(idx, idx)]
        self.sources[(source_phase, "whole")] = Source(names, cov, first)
        self.priors[phase] = carry.CarriedPrior(
            names, carry.drho_gain(ident, names), {(source_phase, "whole"): np.eye(len(names))})
        return ident

    def carried(self, phase: str, ident: Identification) -> Identification:
        """A verification's identification joined with the axes' layout (tilts, gaps)
        and the legs' bows the earlier rounds measured, which no offset changed
        (orthocal.carry; the two are independent measurements, joined one after the
        other): its Δρ gains, never loses. Without an earlier round of its model's
        names: as it is."""
        self.priors.pop(phase, None)
        parts: list[tuple[tuple[str, ...], dict[SourceKey, np.ndarray]]] = []
        for rounds, names, kind in ((self.layout_rounds, accuracy.LAYOUT_NAMES, "layout"),
                                    (self.form_rounds, BOW_NAMES, "form")):
            ident, part = self._carry(phase, ident, rounds, names, kind)
            if part is not None:
                parts.append(part)
        if parts:
            names = tuple(n for held, _ in parts for n in held)
            weights: dict[SourceKey, np.ndarray] = {}
            row = 0
            for held, ws in parts:
                for key, w in ws.items():
                    full = np.zeros((len(names), w.shape[1]))
                    full[row:row + len(held)] = w
                    weights[key] = full
                row += len(held)
            self.priors[phase] = carry.CarriedPrior(names, carry.drho_gain(ident, names),
                                                    weights)
        return ident

    def _carry(self, phase: str, ident: Identification, rounds: list[accuracy.RoundLayout],
               names: tuple[str, ...], kind: str
               ) -> tuple[Identification, tuple[tuple[str, ...], dict[SourceKey, np.ndarray]]
                          | None]:
        """``ident`` joined with the pool of the other rounds' ``names``, and how that
        prior was made: its names and each round's pooling weight Σ_p·Σ_j⁻¹ (None where
        nothing was carried)."""
        held = [n for n in names if n in ident.names]
        others = [r for r in rounds if r.phase != phase]
        prior = accuracy.pool_layout(others)
        if not held or prior is None or not set(held) <= set(prior.names):
            return ident, None
        idx = [prior.names.index(n) for n in held]
        try:
            joined = carry.carried(ident, self.geometry, held,
                                   prior.values[idx], prior.covariance[np.ix_(idx, idx)])
        except (ValueError, np.linalg.LinAlgError):
            return ident, None  # the round's own fit stands
        weights = {(r.phase, kind): (prior.covariance @ np.linalg.inv(r.covariance))[idx]
                   for r in others if r.phase in prior.rounds and r.names == prior.names}
        return joined, (tuple(held), weights)

    def shared(self, phase: str, earlier: Sequence[tuple[str, Identification]]
               ) -> list[np.ndarray]:
        """Round ``phase``'s Δρ̂ covariance (3 × 3) with each earlier round's (``earlier``:
        their phases and identifications, in order) through what it carried from them
        (orthocal.carry.cross_covariance); zero where it carried nothing."""
        prior = self.priors.get(phase)
        if prior is None:
            return [np.zeros((3, 3)) for _ in earlier]
        return [carry.cross_covariance(prior, self.priors.get(p), self._own(p, ident),
                                       self._source_cov) for p, ident in earlier]

    def _own(self, phase: str, ident: Identification) -> dict[SourceKey, np.ndarray]:
        """Cov(Δρ̂, ℓ_s) of round ``phase`` (its identification ``ident``) with each source
        its own data made: the block of its covariance (zero for names its model has
        not: a larger fit of the same data is uncorrelated with the smaller's Δρ there,
        docs/model.md (14))."""
        rows = [ident.names.index(f"drho_{a}") for a in "xyz"]
        cov = np.asarray(ident.covariance)
        out = {}
        for key, source in self.sources.items():
            if key[0] != phase:
                continue
            x = np.zeros((3, len(source.names)))
            for c, name in enumerate(source.names):
                if name in ident.names:
                    x[:, c] = cov[rows, ident.names.index(name)]
            out[key] = x
        return out

    def _source_cov(self, a: SourceKey, b: SourceKey) -> np.ndarray | None:
        """Cov(ℓ_a, ℓ_b): the block of their fit's covariance where one fit made both,
        else None (other rounds' data; two fits of one round's data taken apart)."""
        sa, sb = self.sources.get(a), self.sources.get(b)
        if sa is None or sb is None or sa.fit is not sb.fit:
            return None
        names = list(sa.fit.names)
        ia = [names.index(n) for n in sa.names]
        ib = [names.index(n) for n in sb.names]
        return np.asarray(sa.fit.covariance)[np.ix_(ia, ib)]
