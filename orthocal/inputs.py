"""The deviations as given to an identification: checked and laid out as rows
(one per measured value, a key repeated once per cycle), and the error every
request with bad keys, values or too little data raises."""

from __future__ import annotations

from collections.abc import Iterable, Mapping

import numpy as np

from orthocal.measurement import Key, check_key


class IdentificationError(ValueError):
    """The request cannot be identified (too few deviations, rank deficiency,
    bad keys or values). The message says which and why."""


def flatten_deviations(deviations_in) -> tuple[list[Key], np.ndarray]:
    """Rows (key, value) from a mapping key → float | sequence of floats, or from
    an iterable of (key, value) pairs (repeats allowed in both)."""
    items: Iterable = deviations_in.items() if isinstance(deviations_in, Mapping) else deviations_in
    keys: list[Key] = []
    values: list[float] = []
    for key, value in items:
        key = tuple(key)
        try:
            check_key(key)
        except ValueError as exc:
            raise IdentificationError(str(exc)) from None
        repeats = np.atleast_1d(np.asarray(value, dtype=float))
        if repeats.ndim != 1 or repeats.size == 0:
            raise IdentificationError(f"deviation {key!r} has no value")
        if not np.all(np.isfinite(repeats)):
            raise IdentificationError(f"deviation {key!r} is not a finite number: {value!r}")
        keys.extend([key] * repeats.size)
        values.extend(repeats.tolist())
    return keys, np.asarray(values)
