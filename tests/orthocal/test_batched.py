"""orthocal.batched against orthocal.measurement: the batched deviations of many
parameter vectors are each vector's own deviations (bit for bit where the axes are
straight and meet, within 1e-12 mm where Newton solves them), and the Jacobian built
on them is the central differences of the one-by-one deviations."""

from __future__ import annotations

import numpy as np
import pytest

from orthocal.batched import deviations_batch
from orthocal.geometry import FIT_NAMES, MODELS, Geometry
from orthocal.identification import exact_jacobian
from orthocal.measurement import deviations

GEOMETRY = Geometry()
KEYS = [(sign, leg, d) for sign in ("+", "-", "+30", "-50", "+@0.25", "-@0.75")
        for leg in "xyz" for d in "xyz" if d != leg]


def _params(rng: np.random.Generator, tilted: bool, gapped: bool, bowed: bool) -> np.ndarray:
    P = np.zeros((6, len(FIT_NAMES)))
    P[:, :3] = rng.normal(0.0, 1.0, (6, 3))
    P[:, 3:6] = rng.normal(0.0, 0.3, (6, 3))
    if tilted:
        P[3:, 6:9] = rng.normal(0.0, 2.0, (3, 3))  # the first rows stay straight
    if gapped:
        P[4:, 9:12] = rng.normal(0.0, 0.5, (2, 3))
    if bowed:
        P[:, 12:] = rng.normal(0.0, 0.01, (6, 6))
    return P


@pytest.mark.parametrize("tilted", [False, True])
@pytest.mark.parametrize("gapped", [False, True])
@pytest.mark.parametrize("bowed", [False, True])
@pytest.mark.parametrize("stands", [False, True])
def test_each_row_is_that_vector_s_own_deviations(tilted: bool, gapped: bool, bowed: bool,
                                                   stands: bool) -> None:
    rng = np.random.default_rng(7)
    keys = KEYS + KEYS[:4]  # repeated keys, as the cycles give them
    P = _params(rng, tilted, gapped, bowed)
    offsets = rng.normal(0.0, 3.0, len(keys)) if stands else None
    batch = deviations_batch(keys, GEOMETRY, P, offsets)
    assert batch.shape == (len(P), len(keys))
    for row, params in zip(batch, P, strict=True):
        alone = deviations(keys, GEOMETRY, params, offsets)
        if not params[6:12].any():
            assert np.array_equal(row, alone)  # the closed forms' numbers, bit for bit
        else:
            assert np.max(np.abs(row - alone)) < 1e-12


@pytest.mark.parametrize("model", ["rho", "full+tilt", "rho+tilt+gap"])
def test_the_jacobian_is_the_central_differences_of_the_deviations(model: str) -> None:
    rng = np.random.default_rng(3)
    base = np.zeros(len(FIT_NAMES))
    base[:12] = rng.normal(0.0, 0.5, 12)
    J = exact_jacobian(KEYS, GEOMETRY, base, model)
    h = 1e-5
    for c, col in enumerate(MODELS[model]):
        step = np.zeros(len(FIT_NAMES))
        step[col] = h
        column = (deviations(KEYS, GEOMETRY, base + step)
                  - deviations(KEYS, GEOMETRY, base - step)) / (2 * h)
        assert np.max(np.abs(J[:, c] - column)) < 1e-6  # 1e-12 mm over 2h


def test_a_row_of_the_wrong_length_is_refused() -> None:
    with pytest.raises(ValueError, match="rows of 18 parameters"):
        deviations_batch(KEYS, GEOMETRY, np.zeros((2, 12)))
