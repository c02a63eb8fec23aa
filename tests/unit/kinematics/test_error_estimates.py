"""Yeadon's error estimates and the sigma^2 tau figure: hand values and simulation."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from spotlab.kinematics import KinematicsError
from spotlab.kinematics.error_estimates import (
    equivalent_sd,
    four_combinations,
    repeated_measurement_sd,
    rounding_sd,
    sigma2_tau,
)


def test_rounding_sd_hand_value_and_simulation() -> None:
    assert rounding_sd() == pytest.approx(0.28867513459481287)  # 1 / sqrt(12)
    assert rounding_sd(1e-3) == pytest.approx(1e-3 / math.sqrt(12.0))
    # a millisecond timer read at random instants
    t = np.random.default_rng(1).uniform(0.0, 5000.0, 200_000)
    assert np.std(t - np.round(t)) == pytest.approx(rounding_sd(1.0), rel=0.01)
    with pytest.raises(KinematicsError, match="positive"):
        rounding_sd(0.0)


def test_repeated_measurement_hand_values() -> None:
    x1 = np.array([1.0, 2.0, 3.0, 4.0])
    x2 = np.array([1.0, 4.0, 3.0, 2.0])
    # V_l = (x1 - x2)^2 / 2 = [0, 2, 0, 2]; V_g = 1; delta^2 = 0.25 V_l + 0.75
    got = repeated_measurement_sd(np.stack([x1, x2]))
    assert_allclose(got, np.sqrt([0.75, 1.25, 0.75, 1.25]))
    assert_allclose(
        repeated_measurement_sd(np.stack([x1, x2]), k=1.0), [0, np.sqrt(2), 0, np.sqrt(2)]
    )
    assert_allclose(repeated_measurement_sd(np.stack([x1, x2]), k=0.0), 1.0)


def test_yeadons_bounds_for_k_quarter() -> None:
    rng = np.random.default_rng(2)
    x = rng.normal(0.0, 1.0, (2, 1000)) * rng.uniform(0.1, 3.0, 1000)
    local = 0.5 * (x[0] - x[1]) ** 2
    global_ = local.mean()
    d = repeated_measurement_sd(x)
    assert np.all(d >= 0.5 * np.sqrt(local) - 1e-12)  # underestimated at most 2 times
    assert np.all(d >= math.sqrt(0.75 * global_) - 1e-12)  # about 0.87 V_g^(1/2)
    assert math.sqrt(0.75) == pytest.approx(0.87, abs=0.005)


def test_repeated_measurement_simulation_channels_and_gaps() -> None:
    rng = np.random.default_rng(3)
    truth = np.sin(np.linspace(0, 3, 5000))[:, None] * [1.0, 2.0]
    sigma = np.array([0.5, 2.0])
    x = truth + rng.normal(0.0, 1.0, (3, 5000, 2)) * sigma  # three repetitions
    x[0, :10, 0] = np.nan  # a missing repetition: two are left
    x[1:, 20, 1] = np.nan  # one left: no estimate
    d = repeated_measurement_sd(x)
    assert d.shape == (5000, 2)
    assert np.isnan(d[20, 1]) and np.isfinite(d[:10, 0]).all()
    # E[delta^2] = sigma^2: each repeated value has that standard deviation
    assert_allclose(np.nanmean(d**2, axis=0), sigma**2, rtol=0.03)


def test_repeated_measurement_errors() -> None:
    with pytest.raises(KinematicsError, match="repetitions"):
        repeated_measurement_sd(np.zeros((1, 4)))
    with pytest.raises(KinematicsError, match="k must"):
        repeated_measurement_sd(np.zeros((2, 4)), k=1.5)
    with pytest.raises(KinematicsError, match="measured at least twice"):
        repeated_measurement_sd(np.array([[1.0, np.nan], [np.nan, 2.0]]))
    with pytest.raises(KinematicsError, match="infinite"):
        repeated_measurement_sd(np.array([[1.0, np.inf], [1.0, 2.0]]))


def test_four_combinations_hand_values() -> None:
    mean, sd = four_combinations(10.0, 12.0, 11.0, 13.0)
    assert mean == pytest.approx(11.5)
    # [(10 - 13)^2 + (12 - 11)^2] / 8 = 10 / 8
    assert sd == pytest.approx(math.sqrt(10.0 / 8.0))


def test_four_combinations_simulation() -> None:
    # a_ij = A0 + X_i + Y_j: the estimate's mean equals the mean's true error variance
    rng = np.random.default_rng(4)
    n = 200_000
    sx, sy = 0.3, 0.8
    X = rng.normal(0.0, sx, (2, n))
    Y = rng.normal(0.0, sy, (2, n))
    A0 = 1.0
    mean, sd = four_combinations(
        A0 + X[0] + Y[0], A0 + X[0] + Y[1], A0 + X[1] + Y[0], A0 + X[1] + Y[1]
    )
    expected = 0.5 * sx**2 + 0.5 * sy**2
    assert np.mean(sd**2) == pytest.approx(expected, rel=0.02)
    assert np.var(mean - A0) == pytest.approx(expected, rel=0.02)


def test_four_combinations_of_angles_across_the_wrap() -> None:
    # estimates of the same angle on both sides of +-pi (or 2 pi apart)
    est = np.array(
        [np.pi - 0.01, -np.pi + 0.01, np.pi + 0.01 - 2 * np.pi, np.pi - 0.03 + 2 * np.pi]
    )
    mean, sd = four_combinations(*est, angles=True)
    # aligned to the first: pi - 0.01, pi + 0.01, pi + 0.01, pi - 0.03
    assert mean == pytest.approx(np.pi - 0.005, abs=1e-12)
    assert sd == pytest.approx(math.sqrt(0.02**2 / 8.0), abs=1e-12)
    _, sd_raw = four_combinations(*est)
    assert sd_raw > 1.0


def test_sigma2_tau_compares_systems() -> None:
    assert sigma2_tau(0.1, 0.01) == pytest.approx(1e-4)  # 0.1 mm at 100 Hz: 1e-4 mm^2 s
    # 0.2 mm at 400 Hz has the same figure; averaged over 10 ms it is as precise
    assert sigma2_tau(0.2, 1 / 400) == pytest.approx(sigma2_tau(0.1, 1 / 100))
    noise = np.random.default_rng(5).normal(0.0, 0.2, (100_000, 4))
    assert np.std(noise.mean(axis=1)) == pytest.approx(0.1, rel=0.01)
    assert equivalent_sd(sigma2_tau(0.1, 0.01), 1 / 400) == pytest.approx(0.2)
    with pytest.raises(KinematicsError, match="interval"):
        sigma2_tau(0.1, 0.0)
    with pytest.raises(KinematicsError, match="sd"):
        sigma2_tau(-0.1, 0.01)
    with pytest.raises(KinematicsError, match="figure"):
        equivalent_sd(np.nan, 0.01)
