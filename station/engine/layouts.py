"""What no offset changes, kept round by round (docs/design.md, "Closed loop"): the
axes' layout (tilts, gaps) each round measured, the legs' bows where a second gauge
plane was read, and the fits they came from; a later round joins them
(orthocal.carry)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from orthocal import Identification, carry
from orthocal.geometry import BOW_NAMES, Geometry
from station.analysis import accuracy_statement as accuracy
from station.analysis.model_choice import second_plane
from station.analysis.statistics import Measurement
from station.errors import RunFailed


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

    def add(self, phase: str, m: Measurement, ident: Identification) -> None:
        """The round's axes layout (tilts and gaps): from its own fit if it has them
        all, else from a rho+tilt+gap fit of the same measurement (what the run could
        not rule out; rho+tilt where the gaps cannot be told); a round measured again
        replaces what its earlier passes gave."""
        self.layout_rounds = [t for t in self.layout_rounds if t.phase != phase]
        self.form_rounds = [t for t in self.form_rounds if t.phase != phase]
        form = accuracy.round_form(phase, ident)
        if form is not None:
            if second_plane(ident.keys):
                # The tilts of a round at the legs' middles alone hold the bows (a uniform
                # bow is a tilt there): the round that read both planes replaces them.
                fitted = {t.phase for t in self.form_rounds} | {phase}
                self.layout_rounds = [t for t in self.layout_rounds if t.phase in fitted]
            self.form_rounds.append(form)
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

    def form_fit(self, phase: str) -> Identification | None:
        """The layout fit of the latest round before ``phase``'s that fitted the legs'
        bows (a second gauge plane), or None."""
        fits = [fit for p, fit in self.layout_fits.items()
                if p != phase and all(b in fit.names for b in BOW_NAMES)]
        return fits[-1] if fits else None

    def carried(self, phase: str, ident: Identification) -> Identification:
        """A verification's identification joined with the axes' layout (tilts, gaps)
        and the legs' bows the earlier rounds measured, which no offset changed
        (orthocal.carry; the two are independent measurements, joined one after the
        other): its Δρ gains, never loses. Without an earlier round of its model's
        names: as it is."""
        for rounds, names in ((self.layout_rounds, accuracy.LAYOUT_NAMES),
                              (self.form_rounds, BOW_NAMES)):
            ident = self._carry(phase, ident, rounds, names)
        return ident

    def _carry(self, phase: str, ident: Identification, rounds: list[accuracy.RoundLayout],
               names: tuple[str, ...]) -> Identification:
        held = [n for n in names if n in ident.names]
        prior = accuracy.pool_layout([r for r in rounds if r.phase != phase])
        if not held or prior is None or not set(held) <= set(prior.names):
            return ident
        idx = [prior.names.index(n) for n in held]
        try:
            return carry.carried(ident, self.geometry, held,
                                 prior.values[idx], prior.covariance[np.ix_(idx, idx)])
        except (ValueError, np.linalg.LinAlgError):
            return ident  # the round's own fit stands
