"""Penalised least squares for natural splines of order 2m, GCV and Wood & Jennings.

The smoothing spline of order 2m minimises, over all functions with m
square-integrable derivatives,

    J(g) = sum_i w_i (y_i - g(t_i))^2 + p * integral_{t_1}^{t_N} (g^(m)(t))^2 dt.

Its minimiser is a natural spline of degree 2m - 1 with knots at the samples
(Schoenberg 1964; Reinsch 1967): g^(m) = sum_j gamma_j N_j with N_j the
order-m B-splines of unit integral on x_j .. x_{j+m}. The Peano kernel of the
m-th divided difference gives ``Q^T f = R gamma / m!`` (f the values at the
samples, Q^T the divided-difference matrix, R the Gram matrix of the N_j), so
the penalty is ``(m!)^2 f^T Q R^-1 Q^T f`` and the fit is Reinsch's

    (R + p (m!)^2 Q^T W^-1 Q) delta = Q^T y,   f = y - p (m!)^2 W^-1 Q delta,

a banded system of half-bandwidth m. Unlike the normal equations in a
B-spline basis it stays well conditioned as p grows: Q^T annihilates the
polynomials of degree < m exactly, so the limit p -> infinity is the weighted
least-squares polynomial. ``tr(I - A) = (N - m) - tr(Sigma R)`` with Sigma the
inverse of the banded matrix needs only Sigma's band.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import linalg, optimize

from spotlab.kinematics import _banded

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class FitStatistics:
    """Figures of one fit at one smoothing parameter, one entry per channel.

    Attributes
    ----------
    msr : ndarray, shape (K,)
        Mean weighted squared residual, ``sum(w r^2) / n`` (GCVSPL's WK(2)).
    dof : float
        Effective degrees of freedom of the fit, ``trace(A)``.
    gcv : ndarray, shape (K,)
        ``msr / (1 - dof / n)^2`` (GCVSPL's WK(1)).
    variance : ndarray, shape (K,)
        Gauss-Markov residual variance estimate ``n msr / (n - dof)`` (WK(6)).
    """

    msr: FloatArray
    dof: float
    gcv: FloatArray
    variance: FloatArray


class PenalisedSpline:
    """Reinsch-type banded equations of the smoothing spline of order 2m at samples ``x``.

    Parameters
    ----------
    x : ndarray, shape (N,)
        Strictly increasing sample times.
    w : ndarray, shape (N,)
        Positive weights.
    m : int
        Half the spline order (2 cubic, 3 quintic).
    """

    def __init__(self, x: FloatArray, w: FloatArray, m: int) -> None:
        self.m = m
        self.w = w
        self.winv = 1.0 / w
        self.n_eff = x.size
        self.q = _banded.divided_differences(x, m)
        self.r = _banded.bspline_gram_band(x, m)
        self.qwq = _banded.qwq_band(self.q, self.winv)
        self.factorial2 = float(math.factorial(m) ** 2)
        # p where the fit goes from near-interpolation (spline wavelength ~ the median
        # sample spacing) to the polynomial (wavelength ~ the record): the search range
        order = 2 * m - 1
        w_mean = float(np.mean(w))
        self.log_p_range = (
            order * np.log10(np.median(np.diff(x))) - np.log10(w_mean) - 3.0,
            order * np.log10(x[-1] - x[0]) - np.log10(w_mean) + 3.0,
        )

    def solve(self, p: float, y: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Fitted values (N, K) and the Cholesky factor of ``R + p (m!)^2 Q^T W^-1 Q``."""
        pp = p * self.factorial2
        chol = np.asarray(
            linalg.cholesky_banded(self.r + pp * self.qwq, lower=False, check_finite=False)
        )
        rhs = _banded.qt_times(self.q, y)
        delta = linalg.cho_solve_banded((chol, False), rhs, check_finite=False)
        fitted = y - pp * self.winv[:, None] * _banded.q_times(self.q, delta)
        return fitted, chol

    def statistics(self, p: float, y: FloatArray) -> tuple[FloatArray, FitStatistics]:
        """Fitted values and fit figures at smoothing parameter p."""
        fitted, chol = self.solve(p, y)
        n = self.n_eff
        msr = (self.w[:, None] * (y - fitted) ** 2).sum(axis=0) / n
        # tr(I - A) = p (m!)^2 tr(Sigma Q^T W^-1 Q) = tr(Sigma (M - R)) = (N - m) - tr(Sigma R):
        # only Sigma's band is needed, and no large divided differences enter
        band = _banded.inverse_band(chol)
        rows = self.r.shape[1]
        trace_sr = float(np.dot(band[:, 0], self.r[self.m]))
        for d in range(1, self.m + 1):
            trace_sr += 2.0 * float(np.dot(band[: rows - d, d], self.r[self.m - d, d:]))
        rdof = rows - trace_sr
        rdof = max(rdof, np.finfo(float).tiny)
        gcv = msr / (rdof / n) ** 2
        return fitted, FitStatistics(msr=msr, dof=n - rdof, gcv=gcv, variance=msr * n / rdof)


def _gcv_at(problem: PenalisedSpline, y: FloatArray, log_p: float) -> float:
    try:
        _, stats = problem.statistics(10.0**log_p, y)
    except linalg.LinAlgError:
        return np.inf
    if stats.dof > problem.n_eff * (1.0 - 1e-9):
        return np.inf  # interpolation: the criterion is 0/0 there
    return float(stats.gcv[0])


def minimise_gcv(problem: PenalisedSpline, y: FloatArray, step: float = 2.0) -> float:
    """Smoothing parameter minimising GCV for one channel y (N, 1).

    A scan over ``log10 p`` with one point per ``step`` decades across the
    whole range from near-interpolation to the polynomial brackets the global
    minimum; bounded Brent refinement then locates it to 1e-6 in log10 p
    (GCVSPL searches log p by golden section and parabolic steps as well).
    """
    lo, hi = problem.log_p_range
    grid = np.arange(lo, hi + step, step)
    values = np.array([_gcv_at(problem, y, g) for g in grid])
    if not np.any(np.isfinite(values)):
        return float(10.0 ** grid[-1])
    best = int(np.argmin(values))
    a, b = grid[max(best - 1, 0)], grid[min(best + 1, grid.size - 1)]
    res = optimize.minimize_scalar(
        lambda g: _gcv_at(problem, y, g), bounds=(a, b), method="bounded", options={"xatol": 1e-6}
    )
    return float(10.0**res.x) if res.fun <= values[best] else float(10.0 ** grid[best])


def solve_wood_jennings(problem: PenalisedSpline, y: FloatArray) -> float:
    """Smoothing parameter with ``sum(w r^2) = N`` (Wood & Jennings 1979) for one channel.

    The weighted residual sum grows monotonically with p; when even the
    polynomial of degree m - 1 (p -> infinity) stays within the constraint the
    largest p of the search range is returned, which is that polynomial to
    rounding.
    """
    n = problem.n_eff

    def excess(log_p: float) -> float:
        fitted, _ = problem.solve(10.0**log_p, y)
        return float((problem.w[:, None] * (y - fitted) ** 2).sum() / n - 1.0)

    lo, hi = problem.log_p_range
    hi += 6.0
    while True:  # very large p is singular to working precision for long records
        try:
            top = excess(hi)
            break
        except linalg.LinAlgError:
            hi -= 1.0
    if top <= 0.0:
        return float(10.0**hi)
    while excess(lo) > 0.0:
        lo -= 6.0
    return float(10.0 ** optimize.brentq(excess, lo, hi, xtol=1e-12))
