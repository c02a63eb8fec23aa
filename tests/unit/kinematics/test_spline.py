"""SmoothingSpline: exactness, derivatives, channels, gaps, Wood & Jennings, memory, errors."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest
from numpy.testing import assert_allclose

from spotlab.core.errors import SpotlabError
from spotlab.kinematics import KinematicsError, SmoothingSpline


def _noisy(n: int = 200, seed: int = 1) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    # jittered sampling: near-coincident samples make divided differences (here and
    # in GCVSPL) lose accuracy, see the Notes of SmoothingSpline
    t = np.linspace(0.0, 2.0, n) + rng.uniform(-0.3, 0.3, n) * 2.0 / n
    return t, np.sin(3.0 * t) + 0.05 * rng.standard_normal(n)


@pytest.mark.parametrize(("degree", "coeffs"), [(5, [0.3, -1.2, 2.5]), (3, [0.7, -4.0])])
@pytest.mark.parametrize("p", [None, 1e3, 1e9])
def test_polynomials_below_degree_m_are_reproduced(
    degree: int, coeffs: list[float], p: float | None
) -> None:
    # the penalty vanishes on polynomials of degree < m: no smoothing bias at any p
    rng = np.random.default_rng(2)
    t = np.sort(rng.uniform(-1.0, 3.0, 60))
    poly = np.polynomial.Polynomial(coeffs)
    s = SmoothingSpline(t, poly(t), degree=degree, p=p)
    grid = np.linspace(-1.5, 3.5, 41)  # natural extension outside is the same polynomial
    assert_allclose(s(grid), poly(grid), atol=1e-8)
    assert_allclose(s(grid, nu=1), poly.deriv()(grid), atol=1e-7)


def test_derivatives_of_smooth_noiseless_signal() -> None:
    t = np.linspace(0.0, 1.0, 401)
    s = SmoothingSpline(t, np.sin(2 * np.pi * t), degree=5, p=1e-16)
    inner = t[40:-40]
    w = 2 * np.pi
    assert_allclose(s(inner), np.sin(w * inner), atol=1e-9)
    assert_allclose(s(inner, nu=1), w * np.cos(w * inner), atol=1e-6)
    assert_allclose(s(inner, nu=2), -(w**2) * np.sin(w * inner), atol=1e-4)
    assert_allclose(s(inner, nu=3), -(w**3) * np.cos(w * inner), atol=1e-1)


def test_channels_equal_one_by_one_fits() -> None:
    t, y1 = _noisy(seed=3)
    _, y2 = _noisy(seed=4)
    both = SmoothingSpline(t, np.column_stack([y1, 2.0 * y2 + 1.0]), degree=5)
    one = SmoothingSpline(t, y1, degree=5)
    two = SmoothingSpline(t, 2.0 * y2 + 1.0, degree=5)
    assert_allclose(both.p, [one.p, two.p], rtol=1e-12)
    assert_allclose(both.dof, [one.dof, two.dof], rtol=1e-12)
    assert_allclose(
        both(t, nu=2), np.column_stack([one(t, nu=2), two(t, nu=2)]), rtol=1e-12, atol=1e-9
    )


def test_gcv_attributes_are_consistent() -> None:
    t, y = _noisy()
    s = SmoothingSpline(t, y, degree=5)
    n = t.size
    assert 3 < s.dof < n
    assert_allclose(s.residual_dof, n - s.dof)
    assert_allclose(s.variance, s.msr * n / s.residual_dof)
    assert_allclose(s.gcv, s.msr / (s.residual_dof / n) ** 2)
    assert_allclose(s.variance, 0.05**2, rtol=0.3)  # the noise variance, estimated
    for factor in (0.5, 2.0):  # a minimum of GCV
        other = SmoothingSpline(t, y, degree=5, p=s.p * factor)
        assert other.gcv > s.gcv


def test_wood_jennings_constraint() -> None:
    t, y = _noisy(seed=5)
    sigma = np.full(t.size, 0.05)
    sigma[::7] = 0.1
    s = SmoothingSpline(t, y, sigma=sigma, degree=5)
    assert_allclose(np.sum(((s(t) - y) / sigma) ** 2), t.size, rtol=1e-8)


def test_wood_jennings_with_large_errors_gives_the_polynomial() -> None:
    t = np.linspace(0.0, 1.0, 30)
    y = 1.0 + 2.0 * t + 0.01 * np.sin(20 * t)
    s = SmoothingSpline(t, y, sigma=np.full(30, 10.0), degree=3)
    assert_allclose(s(t), np.polynomial.Polynomial.fit(t, y, 1)(t), atol=1e-6)


def test_nan_samples_are_bridged() -> None:
    t = np.linspace(0.0, 1.0, 201)
    truth = np.sin(2 * np.pi * t)
    y = truth.copy()
    y[80:100] = np.nan
    s = SmoothingSpline(t, np.column_stack([y, truth]), degree=5, p=1e-14)
    assert np.all(np.isfinite(s(t)))
    assert_allclose(s(t)[80:100, 0], truth[80:100], atol=1e-3)
    assert_allclose(s(t)[:, 1], truth, atol=1e-6)
    g = SmoothingSpline(t, y, degree=5)  # GCV counts only the samples present
    assert_allclose(g.residual_dof + g.dof, 181)


def test_fit_is_banded_memory_linear_in_n() -> None:
    # 200 000 samples: an N x N float matrix would be 320 GB; the banded fit needs
    # a few hundred bytes per sample, and the same per sample at a tenth of the size
    rng = np.random.default_rng(6)

    def peak_per_sample(n: int) -> float:
        t = np.arange(n) * 0.01
        y = np.sin(t) + 0.01 * rng.standard_normal(n)
        tracemalloc.start()
        try:
            s = SmoothingSpline(t, y, degree=5, p=1e-6)
            _, peak = tracemalloc.get_traced_memory()
        finally:
            tracemalloc.stop()
        assert np.isfinite(s.dof)
        return peak / n

    small, large = peak_per_sample(20_000), peak_per_sample(200_000)
    assert large < 2_000  # bytes per sample
    assert large < 1.5 * small


@pytest.mark.parametrize(
    ("t", "y", "kwargs", "match"),
    [
        (np.arange(5.0), np.arange(5.0), {"degree": 5}, "at least 6 samples"),
        (np.arange(3.0), np.arange(3.0), {"degree": 3}, "at least 4 samples"),
        (np.array([0.0, 1, 1, 2, 3, 4]), np.zeros(6), {}, "strictly increasing"),
        (np.array([0.0, 2, 1, 3, 4, 5]), np.zeros(6), {}, "strictly increasing"),
        (np.array([0.0, 1, np.nan, 3, 4, 5]), np.zeros(6), {}, "strictly increasing"),
        (np.arange(8.0), np.r_[np.zeros(5), [np.nan] * 3], {}, "non-missing"),
        (np.arange(8.0), np.r_[np.zeros(7), np.inf], {}, "infinite"),
        (np.arange(8.0), np.zeros(7), {}, "shape"),
        (np.zeros((8, 2)), np.zeros(8), {}, "one-dimensional"),
        (np.arange(8.0), np.zeros(8), {"degree": 4}, "degree"),
        (np.arange(8.0), np.zeros(8), {"p": 0.0}, "p must be"),
        (np.arange(8.0), np.zeros(8), {"p": np.nan}, "p must be"),
        (np.arange(8.0), np.zeros(8), {"sigma": np.zeros(8)}, "sigma"),
        (np.arange(8.0), np.zeros(8), {"sigma": np.ones(7)}, "sigma"),
    ],
)
def test_errors(t: np.ndarray, y: np.ndarray, kwargs: dict[str, object], match: str) -> None:
    with pytest.raises(KinematicsError, match=match) as info:
        SmoothingSpline(t, y, **kwargs)  # type: ignore[arg-type]
    assert isinstance(info.value, SpotlabError) and isinstance(info.value, ValueError)


def test_p_too_large_for_the_record() -> None:
    t = np.arange(20_000) * 0.01
    with pytest.raises(KinematicsError, match="too large"):
        SmoothingSpline(t, np.sin(t), degree=5, p=1e30)


@pytest.mark.parametrize(
    ("x", "nu", "match"), [(np.array([0.5]), 4, "nu"), (np.array([np.nan]), 0, "finite")]
)
def test_evaluation_errors(x: np.ndarray, nu: int, match: str) -> None:
    s = SmoothingSpline(np.arange(8.0), np.arange(8.0) ** 2, degree=3, p=1.0)
    with pytest.raises(KinematicsError, match=match):
        s(x, nu=nu)
