"""The identified machine in the controller (orthocal/compensation.py; docs/model.md,
"The geometry in the controller"): (K1) and (K2) undo each other through the exact
kinematics, a controller told the true machine puts the tool where it was sent, and
the prediction (K3) of what the identification's error leaves holds against
machines drawn from that error."""

from __future__ import annotations

import numpy as np
import pytest

from orthocal import Geometry
from orthocal.accuracy import error_field, workspace_grid
from orthocal.compensation import (
    compensated_error,
    compensated_field,
    compensated_interval,
    compensated_points,
    controller_joints,
    landed,
    nominal_path,
)
from orthocal.field_mc import Bounded
from orthocal.kinematics import inverse

G = Geometry()
# The held-out machine of the geometry-in-the-controller work: Δρ left by the offsets
# of a few µm, tilts (0.2, 0.1, −0.15) mrad, gaps (0.15, −0.10, 0.12) mm.
MACHINE = np.array([0.002, -0.001, 0.0015, 0.0, 0.0, 0.0, 0.2, 0.1, -0.15,
                    0.15, -0.10, 0.12])
# The identification's errors the work was sized on: 1 µm per Δρ, 0.01 mrad per tilt,
# 2 µm per gap (standard errors).
SE = np.array([0.001] * 3 + [0.0] * 3 + [0.01] * 3 + [0.002] * 3)


def points(n: int = 200, seed: int = 3) -> np.ndarray:
    return np.random.default_rng(seed).uniform(-100.0, 60.0, (n, 3))


def test_k1_is_the_exact_inverse_of_the_told_machine() -> None:
    p = points()
    rho = controller_joints(p, G, MACHINE)
    assert np.max(np.abs(rho - inverse(p, G, MACHINE[:3], MACHINE[3:6], MACHINE[6:9],
                                       MACHINE[9:]))) == 0.0
    # and the told machine puts the tool back on p
    assert np.max(np.abs(landed(rho, G, MACHINE) - p)) < 1e-9


def test_k2_and_the_nominal_path_undo_each_other() -> None:
    p = points()
    sent = compensated_points(p, G, MACHINE)
    # the program's points move by tens of µm up to a few tenths of a mm, not by nothing
    moved = np.linalg.norm(sent - p, axis=1)
    assert 0.005 < float(np.median(moved)) < 0.5
    assert np.max(np.abs(nominal_path(sent, G, MACHINE) - p)) < 1e-9
    # the nominal controller commands exactly the joints the told machine needs
    assert np.max(np.abs(inverse(sent, G) - controller_joints(p, G, MACHINE))) < 1e-9


def test_a_square_machine_whose_axes_meet_is_compensated_by_nothing() -> None:
    p = points()
    assert np.max(np.abs(compensated_points(p, G, np.zeros(12)) - p)) < 1e-9


def test_told_the_truth_the_tool_lands_where_it_was_sent() -> None:
    grid = workspace_grid(None, 7, G).points
    assert np.max(np.abs(compensated_error(grid, G, MACHINE, MACHINE))) < 1e-9
    # while the nominal kinematics leave tens of µm (docs/model.md: 31.4 µm for these gaps)
    nominal = error_field(grid, G, MACHINE, None).rms_mm
    assert 0.02 < nominal < 0.06


def test_what_is_not_told_is_the_field_it_makes() -> None:
    """A controller told no tilts and gaps leaves the field the offsets-only route
    leaves for the same machine (Δρ told in both)."""
    grid = workspace_grid(None, 7, G).points
    told = MACHINE.copy()
    told[6:] = 0.0
    comp = compensated_field(grid, G, MACHINE, told)
    plain = error_field(grid, G, MACHINE, -MACHINE[:3])  # offsets −Δρ: joints exact
    assert comp.rms_mm == pytest.approx(plain.rms_mm, rel=1e-6)
    iv = compensated_interval(told, MACHINE, np.zeros((12, 12)), None, grid)
    assert iv.rms_mm == pytest.approx(plain.rms_mm, rel=1e-6)
    assert iv.rms_interval_mm == pytest.approx((iv.rms_mm, iv.rms_mm))


def true_rms(draws: np.ndarray, grid: np.ndarray, told: np.ndarray) -> np.ndarray:
    return np.array([compensated_field(grid, G, told + d, told).rms_mm for d in draws])


def test_the_prediction_is_what_machines_drawn_from_the_error_leave() -> None:
    """Machines drawn from the covariance the prediction is given (another seed),
    judged by the exact model: the predicted RMS is their mean, each point's root
    mean square their root mean square, and the 95 % interval holds 95 % of them,
    neither too narrow nor too wide."""
    grid = workspace_grid(None, 5, G).points
    cov = np.diag(SE**2)
    iv = compensated_interval(MACHINE, MACHINE, cov, None, grid, draws=4000, seed=0)
    rng = np.random.default_rng(11)
    draws = rng.standard_normal((1000, 12)) * SE
    truth = true_rms(draws, grid, MACHINE)
    assert iv.rms_mm == pytest.approx(float(np.mean(truth)), rel=0.03)
    inside = np.mean((truth >= iv.rms_interval_mm[0]) & (truth <= iv.rms_interval_mm[1]))
    assert 0.93 <= inside <= 0.97
    # the sizes the work was planned on: about a micrometre at the tool
    assert 0.0005 < iv.rms_mm < 0.002
    assert iv.rms_interval_mm[0] < iv.rms_mm < iv.rms_interval_mm[1]
    assert iv.max_interval_mm[0] < iv.max_mm < iv.max_interval_mm[1]
    assert iv.point_rms_mm.shape == (len(grid),)
    assert float(np.sqrt(np.mean(iv.point_rms_mm**2))) == pytest.approx(
        float(np.sqrt(np.mean(truth**2))), rel=0.03)


def test_a_systematic_error_is_drawn_with_the_statistical_one() -> None:
    """A systematic part (known by its covariance: normal) or a bounded one
    (rectangular) is an error of the machine the controller was told like the
    statistical one: drawn with it, it moves the whole distribution of the field
    left, value and both ends, and the interval holds machines drawn from both."""
    grid = workspace_grid(None, 5, G).points
    cov = np.diag(SE**2)
    form = np.zeros((12, 12))
    form[6:9, 6:9] = np.eye(3) * 0.03**2  # tilts off by a few hundredths of a mrad
    plain = compensated_interval(MACHINE, MACHINE, cov, None, grid)
    wide = compensated_interval(MACHINE, MACHINE, cov, None, grid, systematic=form)
    assert wide.rms_mm > 1.5 * plain.rms_mm
    assert wide.rms_interval_mm[0] > plain.rms_interval_mm[0]
    assert wide.rms_interval_mm[1] > 1.5 * plain.rms_interval_mm[1]
    rng = np.random.default_rng(12)
    draws = rng.standard_normal((600, 12)) * np.sqrt(SE**2 + np.diag(form))
    truth = true_rms(draws, grid, MACHINE)
    inside = np.mean((truth >= wide.rms_interval_mm[0]) & (truth <= wide.rms_interval_mm[1]))
    assert 0.92 <= inside <= 0.98
    # the same tilts bounded by ±0.03·√3 (the same variance), drawn rectangular
    cols = np.zeros((12, 3))
    cols[6:9] = np.eye(3)
    box = compensated_interval(MACHINE, MACHINE, cov, None, grid,
                               bounded=Bounded(cols, [0.03 * np.sqrt(3)] * 3))
    draws = rng.standard_normal((600, 12)) * SE
    draws[:, 6:9] += rng.uniform(-1, 1, (600, 3)) * 0.03 * np.sqrt(3)
    truth = true_rms(draws, grid, MACHINE)
    inside = np.mean((truth >= box.rms_interval_mm[0]) & (truth <= box.rms_interval_mm[1]))
    assert 0.92 <= inside <= 0.98


def test_a_point_beyond_a_legs_reach_has_no_joints() -> None:
    with pytest.raises(ValueError, match="reach"):
        controller_joints(np.array([[0.0, 0.0, 400.0]]), G, MACHINE)
