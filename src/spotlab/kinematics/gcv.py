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
from numpy.polynomial.legendre import leggauss
from numpy.typing import NDArray

from spotlab.core import native
from spotlab.kinematics import _banded
from spotlab.kinematics._brent import bounded_brent, bracketed_brent, minimise

FloatArray = NDArray[np.float64]

#: The compiled kernel (``_c_gcv.c``); without it the numpy code here is its twin.
KERNEL = "spotlab.kinematics._c_gcv"
#: The compiled bands (``_c_bands.c``); without it ``_banded``'s twins make them.
BANDS_KERNEL = "spotlab.kinematics._c_bands"


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


def median(values: FloatArray) -> float:
    """``np.median`` of a finite 1-D array, its arithmetic without its NaN check.

    ``np.median`` imports ``numpy.ma`` (~20 ms) on its first call for that check.
    """
    n = values.size
    half = n // 2
    if n % 2:
        return float(np.partition(values, half)[half])
    part = np.partition(values, [half - 1, half])
    return float((part[half - 1] + part[half]) / 2.0)


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
        self.kernel = native.load(KERNEL)
        bands = native.load(BANDS_KERNEL)
        if bands is not None:
            # the kernel writes the bands column after column: their transposes are
            # LAPACK's column-major band layout, as the twin keeps them
            rows = x.size - m
            self.q = np.empty((rows, m + 1))
            qwq, r = np.empty((rows, m + 1)), np.empty((rows, m + 1))
            nodes, weights = leggauss(m)
            bands.bands(
                np.ascontiguousarray(x, dtype=np.float64), np.ascontiguousarray(self.winv),
                nodes, weights, self.q, qwq, r, m, x.size,
            )  # fmt: skip
            self.r, self.qwq = r.T, qwq.T
        else:
            self.q = _banded.divided_differences(x, m)
            # LAPACK's band layout is column-major: keep the bands so, to factor in place
            self.r = np.asfortranarray(_banded.bspline_gram_band(x, m))
            self.qwq = np.asfortranarray(_banded.qwq_band(self.q, self.winv))
        # the numpy twin's work arrays, made when first needed (the kernel has its own)
        self._work_band: FloatArray | None = None
        self._trace_work: _banded.InverseTrace | None = None
        self.factorial2 = float(math.factorial(m) ** 2)
        # p where the fit goes from near-interpolation (spline wavelength ~ the median
        # sample spacing) to the polynomial (wavelength ~ the record): the search range
        order = 2 * m - 1
        w_mean = float(np.mean(w))
        self.log_p_range = (
            order * np.log10(median(np.diff(x))) - np.log10(w_mean) - 3.0,
            order * np.log10(x[-1] - x[0]) - np.log10(w_mean) + 3.0,
        )

    @property
    def _work(self) -> FloatArray:
        if self._work_band is None:
            self._work_band = np.empty_like(self.r, order="F")
        return self._work_band

    @property
    def _trace(self) -> _banded.InverseTrace:
        if self._trace_work is None:
            self._trace_work = _banded.InverseTrace(self.r)
        return self._trace_work

    def kernel_arrays(self) -> tuple[FloatArray, ...]:
        """q, r, qwq, w, 1/w as the kernel reads them (C-contiguous views, no copies)."""
        # the bands are column-major (m + 1, N - m): their transposes are C-contiguous
        return self.q, self.r.T, self.qwq.T, self.w, self.winv

    def fit(
        self, p: float, y: FloatArray, trace: bool = True
    ) -> tuple[FloatArray, FloatArray, float]:
        """Fitted values (N, K), ``sum(w r^2)`` (K,) and ``n - dof`` at p, by the kernel.

        ``n - dof`` is floored at the smallest normal float as in :meth:`statistics`, and
        is 0.0 when ``trace`` is False (not computed). Only with the kernel loaded.

        Raises
        ------
        numpy.linalg.LinAlgError
            When the banded matrix is not positive definite to working precision.
        """
        assert self.kernel is not None, "the compiled kernel is not loaded"
        y = np.ascontiguousarray(y, dtype=np.float64)
        fitted = np.empty_like(y)
        rss = np.empty(y.shape[1])
        rdof = self.kernel.fit(
            *self.kernel_arrays(), y, fitted, rss, self.m, y.shape[0], y.shape[1],
            float(p), self.factorial2, trace,
        )  # fmt: skip
        if rdof is None:
            raise np.linalg.LinAlgError("banded matrix not positive definite")
        return fitted, rss, float(rdof)

    def factor(self, p: float) -> FloatArray:
        """Upper banded Cholesky factor of ``R + p (m!)^2 Q^T W^-1 Q``, shape (m + 1, N - m).

        The factor lives in a work array that the next call overwrites.

        Raises
        ------
        numpy.linalg.LinAlgError
            When the matrix is not positive definite to working precision.
        """
        from scipy.linalg import lapack  # the twin's: SciPy only where it runs

        work = self._work
        np.multiply(self.qwq, p * self.factorial2, out=work)
        work += self.r
        chol, info = lapack.dpbtrf(work, lower=0, overwrite_ab=1)
        if info != 0:
            raise np.linalg.LinAlgError(f"{info}-th leading minor not positive definite")
        return np.asarray(chol)

    def traces(self, chol: FloatArray) -> FloatArray:
        """``tr(inv(A) R)`` (C,) for factors (C, m + 1, N - m) of this matrix at C values of p."""
        return self._trace.many(chol)

    @property
    def inverse_trace(self) -> _banded.InverseTrace:
        """``tr(inv(A) R)`` of factors of this matrix, loaded one at a time (for batches)."""
        return self._trace

    def solve(
        self, p: float, y: FloatArray, rhs: FloatArray | None = None
    ) -> tuple[FloatArray, FloatArray]:
        """Fitted values (N, K) and the Cholesky factor of ``R + p (m!)^2 Q^T W^-1 Q``.

        ``rhs`` is ``Q^T y`` when the caller has it (it does not depend on p).
        """
        from scipy.linalg import lapack

        chol = self.factor(p)
        if rhs is None:
            rhs = _banded.qt_times(self.q, y)
        delta, info = lapack.dpbtrs(chol, rhs, lower=0)
        if info != 0:  # pragma: no cover - dpbtrs fails only on bad arguments
            raise np.linalg.LinAlgError(f"banded solve failed (info {info})")
        fitted = y - (p * self.factorial2) * self.winv[:, None] * _banded.q_times(self.q, delta)
        return fitted, chol

    def statistics(
        self, p: float, y: FloatArray, rhs: FloatArray | None = None
    ) -> tuple[FloatArray, FitStatistics]:
        """Fitted values and fit figures at smoothing parameter p."""
        n = self.n_eff
        if self.kernel is not None:
            fitted, rss, rdof = self.fit(p, y)
            msr = rss / n
        else:
            fitted, chol = self.solve(p, y, rhs)
            msr = (self.w[:, None] * (y - fitted) ** 2).sum(axis=0) / n
            # tr(I - A) = p (m!)^2 tr(Sigma Q^T W^-1 Q) = tr(Sigma (M - R)) = (N - m) -
            # tr(Sigma R): only Sigma's band is needed, and no large divided differences enter
            rdof = self.r.shape[1] - self._trace(chol)
            rdof = max(rdof, np.finfo(float).tiny)
        gcv = msr / (rdof / n) ** 2
        return fitted, FitStatistics(msr=msr, dof=n - rdof, gcv=gcv, variance=msr * n / rdof)


class _Criterion:
    """GCV of one channel as a function of ``log10 p``, remembering every value."""

    def __init__(self, parts: list[tuple[PenalisedSpline, FloatArray]]) -> None:
        # several parts make one criterion: residuals and degrees of freedom add up
        self.parts = [(problem, y, _banded.qt_times(problem.q, y)) for problem, y in parts]
        self.n = sum(problem.n_eff for problem, _ in parts)
        self.seen: dict[float, float] = {}
        # the fit at the smallest value so far (one part only): the caller needs it last
        self.best: tuple[float, float, FloatArray, FitStatistics] | None = None

    def __call__(self, log_p: float) -> float:
        key = float(log_p)
        if key not in self.seen:
            self.seen[key] = self._evaluate(key)
        return self.seen[key]

    def _evaluate(self, log_p: float) -> float:
        rss = rdof = 0.0
        for problem, y, rhs in self.parts:
            try:
                fitted, stats = problem.statistics(10.0**log_p, y, rhs)
            except np.linalg.LinAlgError:
                return np.inf
            rss += float(stats.msr[0]) * problem.n_eff
            rdof += problem.n_eff - stats.dof
        if rdof < self.n * 1e-9:
            return np.inf  # interpolation: the criterion is 0/0 there
        value = (rss / self.n) / (rdof / self.n) ** 2
        if len(self.parts) == 1 and (self.best is None or value < self.best[0]):
            self.best = (value, log_p, fitted, stats)
        return value

    def fit_at(self, log_p: float) -> tuple[FloatArray, FitStatistics] | None:
        """The fit already computed at ``log_p`` if it was the best one, else None."""
        if self.best is not None and self.best[1] == float(log_p):
            return self.best[2], self.best[3]
        return None


def _scan_and_refine(
    criterion: _Criterion, lo: float, hi: float, step: float, xatol: float
) -> float:
    """log10 p of the smallest criterion on a grid over [lo, hi], refined by Brent."""
    grid = np.arange(lo, hi + step, step)
    values = np.array([criterion(g) for g in grid])
    if not np.any(np.isfinite(values)):
        return float(grid[-1])
    best = int(np.argmin(values))
    a, b = grid[max(best - 1, 0)], grid[min(best + 1, grid.size - 1)]
    # SciPy's minimize_scalar(method="bounded") step for step (_brent)
    x, fun = minimise(bounded_brent(float(a), float(b), xatol), criterion)
    return x if fun <= values[best] else float(grid[best])


#: Records longer than this are searched from a start value (see :func:`minimise_gcv`).
LONG_RECORD = 50_000
#: Segments, and samples per segment, that give a long record's start value.
START_SEGMENTS = 4
START_SEGMENT_LENGTH = 4_000


def _start_value(problem: PenalisedSpline, x: FloatArray, y: FloatArray) -> float:
    """log10 p minimising the joint GCV of a few segments spread over the record."""
    n = x.size
    starts = np.linspace(0, n - START_SEGMENT_LENGTH, START_SEGMENTS).astype(int)
    parts = [
        (
            PenalisedSpline(
                x[s : s + START_SEGMENT_LENGTH], problem.w[s : s + START_SEGMENT_LENGTH], problem.m
            ),
            y[s : s + START_SEGMENT_LENGTH],
        )
        for s in starts
    ]
    lo, hi = problem.log_p_range
    return _scan_and_refine(_Criterion(parts), lo, hi, step=2.0, xatol=1e-2)


def _bracket(criterion: _Criterion, start: float, lo: float, hi: float) -> tuple[float, ...]:
    """Three values of log10 p around a local minimum of the criterion, walking from start."""
    step = 0.25
    a, b = start, start + step
    if criterion(b) > criterion(a):
        a, b, step = b, a, -step  # walk downhill: towards smaller p
    c = b + step
    while criterion(c) < criterion(b):
        if not lo - 10.0 < c < hi + 10.0:
            break  # no interior minimum: the criterion keeps falling to an end
        step *= 2.0
        a, b, c = b, c, c + step
    return (a, b, c) if a < c else (c, b, a)


def gcv_fit(
    problem: PenalisedSpline, y: FloatArray, step: float = 2.0, x: FloatArray | None = None
) -> tuple[float, FloatArray, FitStatistics]:
    """Smoothing parameter minimising GCV for one channel y (N, 1), with its fit.

    Returns p, the fitted values (N, 1) and the figures of the fit at p.

    Up to :data:`LONG_RECORD` samples, a scan over ``log10 p`` with one point per
    ``step`` decades across the whole range from near-interpolation to the
    polynomial brackets the global minimum; bounded Brent refinement then
    locates it to 1e-6 in log10 p (GCVSPL searches log p by golden section and
    parabolic steps as well).

    Longer records (``x``, the sample times, given) are searched like GCVSPL
    searches every record: from a start value, walking until GCV rises, then
    Brent to a relative 1e-5 in log10 p (p to about 1e-4). GCVSPL starts where the fit has N/2
    degrees of freedom; here the start is the joint GCV minimum of
    :data:`START_SEGMENTS` segments of :data:`START_SEGMENT_LENGTH` samples spread
    over the record (a stationary signal has the same p on a segment as on the
    whole), so a few full-size evaluations suffice. The walk finds the local
    minimum nearest to that start.
    """
    if problem.kernel is not None and (x is None or problem.n_eff <= LONG_RECORD):
        ps, fitted, each = search_native(problem, y, step)
        return float(ps[0]), fitted, each[0]
    criterion = _Criterion([(problem, y)])
    lo, hi = problem.log_p_range
    if x is None or problem.n_eff <= LONG_RECORD:
        log_p = _scan_and_refine(criterion, lo, hi, step, xatol=1e-6)
    else:
        a, b, c = _bracket(criterion, _start_value(problem, x, y), lo, hi)
        if criterion(b) < min(criterion(a), criterion(c)):
            # SciPy's minimize_scalar(method="brent", tol=1e-5) step for step (_brent)
            log_p, _ = minimise(bracketed_brent(a, b, c, tol=1e-5), criterion)
        else:
            log_p = min((a, b, c), key=criterion)
    p = float(10.0**log_p)
    known = criterion.fit_at(log_p)
    if known is not None:
        return p, known[0], known[1]
    fitted, stats = problem.statistics(p, y)
    return p, fitted, stats


def search_native(
    problem: PenalisedSpline, y: FloatArray, step: float = 2.0
) -> tuple[FloatArray, FloatArray, list[FitStatistics]]:
    """The scan-and-refine search of :func:`gcv_fit` for every channel of y (N, K), compiled.

    One kernel call: the scan's factors and traces are shared by the channels, the
    Brent refinements (:func:`~spotlab.kinematics._brent.bounded_brent`'s arithmetic)
    run channel by channel. Returns p (K,), the fitted values (N, K) and each channel's
    figures, as :func:`~spotlab.kinematics.gcv_batch.gcv_fit_many` does.

    Raises
    ------
    numpy.linalg.LinAlgError
        When the banded matrix at a channel's chosen p is not positive definite.
    """
    assert problem.kernel is not None, "the compiled kernel is not loaded"
    y = np.ascontiguousarray(y, dtype=np.float64)
    n, k = y.shape
    lo, hi = problem.log_p_range
    grid = np.arange(lo, hi + step, step)
    fitted = np.empty_like(y)
    log_p, rss, rdof = np.empty(k), np.empty(k), np.empty(k)
    failures = problem.kernel.search(
        *problem.kernel_arrays(), y, fitted, grid, log_p, rss, rdof, problem.m, n, k,
        problem.factorial2, 1e-6,
    )  # fmt: skip
    if failures:
        raise np.linalg.LinAlgError(f"{failures} channel(s): banded matrix not positive definite")
    stats = []
    for j in range(k):
        msr = np.array([rss[j] / n])
        stats.append(
            FitStatistics(
                msr=msr, dof=n - rdof[j], gcv=msr / (rdof[j] / n) ** 2, variance=msr * n / rdof[j]
            )
        )
    # p as Python floats, like the numpy search (numpy's power may differ in the last bit)
    return np.array([10.0 ** float(v) for v in log_p]), fitted, stats


def solve_wood_jennings(problem: PenalisedSpline, y: FloatArray) -> float:
    """Smoothing parameter with ``sum(w r^2) = N`` (Wood & Jennings 1979) for one channel.

    The weighted residual sum grows monotonically with p; when even the
    polynomial of degree m - 1 (p -> infinity) stays within the constraint the
    largest p of the search range is returned, which is that polynomial to
    rounding.
    """
    from scipy import optimize

    n = problem.n_eff

    def excess(log_p: float) -> float:
        if problem.kernel is not None:
            return float(problem.fit(10.0**log_p, y, trace=False)[1].sum() / n - 1.0)
        fitted, _ = problem.solve(10.0**log_p, y)
        return float((problem.w[:, None] * (y - fitted) ** 2).sum() / n - 1.0)

    lo, hi = problem.log_p_range
    hi += 6.0
    while True:  # very large p is singular to working precision for long records
        try:
            top = excess(hi)
            break
        except np.linalg.LinAlgError:
            hi -= 1.0
    if top <= 0.0:
        return float(10.0**hi)
    while excess(lo) > 0.0:
        lo -= 6.0
    return float(10.0 ** optimize.brentq(excess, lo, hi, xtol=1e-12))
