"""The trace of inv(A) R from Takahashi's recursion, against dense linear algebra."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import linalg

from spotlab.kinematics import _banded


def _dense(band: np.ndarray) -> np.ndarray:
    """Symmetric dense matrix from upper band storage (bw + 1, n)."""
    bw, n = band.shape[0] - 1, band.shape[1]
    out = np.zeros((n, n))
    for d in range(bw + 1):
        idx = np.arange(n - d)
        out[idx, idx + d] = band[bw - d, d:]
        out[idx + d, idx] = band[bw - d, d:]
    return out


@pytest.mark.parametrize(("n", "bw"), [(1, 2), (5, 3), (37, 2), (101, 3), (1000, 3)])
def test_trace_matches_dense_inverse(n: int, bw: int) -> None:
    rng = np.random.default_rng(n)
    a = rng.standard_normal((bw + 1, n)) * 0.3
    a[bw] = np.abs(a[bw]) + 2.0 * bw  # diagonally dominant: positive definite
    r = rng.standard_normal((bw + 1, n))
    for d in range(1, bw + 1):
        a[bw - d, :d] = 0.0  # unused corner of the band storage
        r[bw - d, :d] = 0.0
    chol = linalg.cholesky_banded(a, lower=False)
    expected = np.trace(np.linalg.inv(_dense(a)) @ _dense(r))
    trace = _banded.InverseTrace(r)
    assert trace(chol) == pytest.approx(expected, rel=1e-11)
    # the work arrays are reused: a second factor of the same size gives its own trace
    a[bw] += 1.0
    chol2 = linalg.cholesky_banded(a, lower=False)
    assert trace(chol2) == pytest.approx(np.trace(np.linalg.inv(_dense(a)) @ _dense(r)), rel=1e-11)


def test_gram_band_is_the_integral_of_products() -> None:
    # order-3 B-splines of unit integral on uneven knots: the Gram matrix by brute force
    from scipy.interpolate import BSpline

    x = np.cumsum(np.random.default_rng(3).uniform(0.5, 1.5, 12))
    m = 3
    band = _banded.bspline_gram_band(x, m)
    rows = x.size - m
    grid = np.linspace(x[0], x[-1], 200_001)
    basis = []
    for j in range(rows):
        spline = BSpline.basis_element(x[j : j + m + 1], extrapolate=False)
        values = np.nan_to_num(spline(grid)) * m / (x[j + m] - x[j])
        basis.append(values)
    dense = np.array([[np.trapezoid(bj * bk, grid) for bk in basis] for bj in basis])
    assert np.allclose(_dense(band), dense, rtol=1e-6, atol=1e-9)


@pytest.mark.parametrize("signal", ["sine", "steps"])
def test_long_record_search_finds_the_scan_minimum(signal: str) -> None:
    # above LONG_RECORD the search starts from segments and walks; the full scan over
    # the whole p range must agree with it
    from spotlab.kinematics.gcv import LONG_RECORD, PenalisedSpline, gcv_fit

    n = LONG_RECORD + 10_000
    t = np.arange(n) * 0.01
    truth = np.sin(np.pi * t) if signal == "sine" else np.tanh((t % 200.0 - 100.0) / 3.0)
    y = (truth + 0.01 * np.random.default_rng(1).standard_normal(n))[:, None]
    problem = PenalisedSpline(t, np.ones(n), 3)
    p_walk, fitted_walk, stats_walk = gcv_fit(problem, y, x=t)
    p_scan, fitted_scan, stats_scan = gcv_fit(problem, y)
    assert p_walk == pytest.approx(p_scan, rel=1e-3)
    assert stats_walk.gcv[0] == pytest.approx(stats_scan.gcv[0], rel=1e-8)
    assert np.allclose(fitted_walk, fitted_scan, rtol=0, atol=1e-5)  # noise SD is 1e-2
