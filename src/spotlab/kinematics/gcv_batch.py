"""GCV searches of many channels that share their sample times and weights, batched.

The channels of one :class:`~spotlab.kinematics.gcv.PenalisedSpline` share the
banded matrix ``R + p (m!)^2 Q^T W^-1 Q`` and hence, at one p, its Cholesky factor
and the trace of the hat matrix; only the right-hand sides differ. The search
is the one :func:`~spotlab.kinematics.gcv.gcv_fit` runs on each channel (a scan
over ``log10 p``, then bounded Brent refinement), with the same evaluations in
the same order, so the results are the per-channel ones to rounding:

* the scan evaluates every channel at each grid point with one factorisation,
  one multi-right-hand-side solve and one trace, the traces of all grid points
  in one recursion;
* the refinements, whose points differ from channel to channel, run in
  lockstep: each channel's bounded Brent search
  (:func:`~spotlab.kinematics._brent.bounded_brent`, SciPy's
  ``minimize_scalar(method="bounded")`` step for step) is a generator that
  yields its next point, and each round factors the channels' matrices, hands
  each factor to the trace as it comes and computes all their traces in one
  recursion.

Fits are computed :data:`COLUMN_BLOCK` channels at a time, so that their
(N, channels) temporaries stay small; every column's arithmetic is the
one-channel one whatever the block.
"""

from __future__ import annotations

from collections.abc import Callable, Generator

import numpy as np
from numpy.typing import NDArray

from spotlab.kinematics import _banded
from spotlab.kinematics._brent import bounded_brent
from spotlab.kinematics.gcv import (
    LONG_RECORD,
    FitStatistics,
    PenalisedSpline,
    gcv_fit,
    search_native,
)

FloatArray = NDArray[np.float64]


def _criterion(rss: FloatArray, rdof: FloatArray, n: int) -> FloatArray:
    """GCV from ``sum(w r^2)`` and ``n - dof``, with the per-channel search's operations."""
    rss = (rss / n) * n  # the per-channel search goes through the mean
    rdof = n - (n - rdof)  # and through dof
    with np.errstate(divide="ignore", invalid="ignore"):
        value = (rss / n) / (rdof / n) ** 2
    return np.where(rdof < n * 1e-9, np.inf, value)


def _rdof(problem: PenalisedSpline, chols: FloatArray | list[FloatArray]) -> FloatArray:
    """``n - dof`` for each factor, floored as :meth:`PenalisedSpline.statistics` floors it."""
    traces = problem.traces(np.asarray(chols))
    return np.maximum(problem.r.shape[1] - traces, np.finfo(float).tiny)


def _fits(
    problem: PenalisedSpline, p: float, chol: FloatArray, y: FloatArray, rhs: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Fitted values (N, K) and ``sum(w r^2)`` (K,) for the columns of y at one factor."""
    from scipy.linalg import lapack  # SciPy only where the twin runs

    delta, info = lapack.dpbtrs(chol, rhs, lower=0)
    if info != 0:  # pragma: no cover - dpbtrs fails only on bad arguments
        raise np.linalg.LinAlgError(f"banded solve failed (info {info})")
    fitted = y - (p * problem.factorial2) * problem.winv[:, None] * _banded.q_times(
        problem.q, delta
    )
    # contiguous rows: each sum runs in the order of a one-column sum
    rss = np.ascontiguousarray((problem.w[:, None] * (y - fitted) ** 2).T).sum(axis=1)
    return fitted, rss


class _Channels:
    """Criterion evaluations of many channels; remembers each channel's best fit."""

    def __init__(self, problem: PenalisedSpline, y: FloatArray) -> None:
        self.problem = problem
        self.y = y
        self.rhs = _banded.qt_times(problem.q, y)
        k = y.shape[1]
        self.best_value = np.full(k, np.inf)
        self.best_log_p = np.full(k, np.nan)
        self.best_fit = np.zeros_like(y)
        self.best_rss = np.zeros(k)
        self.best_rdof = np.zeros(k)

    def _keep(
        self,
        cols: NDArray[np.intp],
        values: FloatArray,
        log_p: float | FloatArray,
        fit: FloatArray,
        rss: FloatArray,
        rdof: float | FloatArray,
    ) -> None:
        """Remember the fits of channels ``cols`` (fit (N, len(cols))) that beat their best.

        ``log_p`` and ``rdof`` are one value for all the channels or one each.
        """
        better = values < self.best_value[cols]
        if np.any(better):
            chosen = cols[better]
            self.best_value[chosen] = values[better]
            self.best_log_p[chosen] = log_p if np.isscalar(log_p) else np.asarray(log_p)[better]
            self.best_fit[:, chosen] = fit[:, better]
            self.best_rss[chosen] = rss[better]
            self.best_rdof[chosen] = rdof if np.isscalar(rdof) else np.asarray(rdof)[better]

    def scan(self, grid: FloatArray) -> FloatArray:
        """Criterion of every channel at every grid point, shape (G, K)."""
        problem, n = self.problem, self.problem.n_eff
        values = np.full((grid.size, self.y.shape[1]), np.inf)
        chols, rows = [], []
        for g, log_p in enumerate(grid):
            try:
                chols.append(np.array(problem.factor(10.0 ** float(log_p))))
            except np.linalg.LinAlgError:
                continue
            rows.append(g)
        if not chols:
            return values
        # traces first (one recursion for all grid points), then one grid point's fits at a
        # time, a block of channels at a time (their temporaries are as large as the block)
        for g, r, chol in zip(rows, _rdof(problem, chols), chols, strict=True):
            p = 10.0 ** float(grid[g])
            for cols in _column_blocks(self.y.shape[1]):
                fitted, rss = _fits(problem, p, chol, self.y[:, cols], self.rhs[:, cols])
                values[g, cols] = _criterion(rss, np.full(rss.shape, r), n)
                self._keep(cols, values[g, cols], float(grid[g]), fitted, rss, float(r))
        return values

    def evaluate(self, points: dict[int, float]) -> dict[int, float]:
        """Criterion of channel k at ``log10 p = points[k]``, each at its own p."""
        from scipy.linalg import lapack

        problem, n = self.problem, self.problem.n_eff
        out = dict.fromkeys(points, float(np.inf))
        # channels asking for the same p (the first Brent point of a shared bracket) share
        # its factor and trace
        sharing: dict[float, list[int]] = {}
        for k, log_p in points.items():
            sharing.setdefault(log_p, []).append(k)
        trace = problem.inverse_trace
        trace.prepare(len(sharing))
        delta = np.empty((problem.r.shape[1], len(points)))
        ks: list[int] = []
        log_ps: list[float] = []
        which: list[int] = []  # the factor of each evaluation
        factors = 0
        for log_p, members in sharing.items():
            try:
                chol = problem.factor(10.0**log_p)
            except np.linalg.LinAlgError:
                continue
            # the trace keeps what it needs: the next factor overwrites this one
            trace.load(factors, chol)
            for k in members:
                solved, info = lapack.dpbtrs(chol, self.rhs[:, k : k + 1], lower=0)
                if info != 0:  # pragma: no cover - dpbtrs fails only on bad arguments
                    raise np.linalg.LinAlgError(f"banded solve failed (info {info})")
                delta[:, len(ks)] = solved[:, 0]
                which.append(factors)
                ks.append(k)
                log_ps.append(log_p)
            factors += 1
        if not ks:
            return out
        rdof = np.maximum(problem.r.shape[1] - trace.run(factors), np.finfo(float).tiny)[which]
        cols = np.array(ks, dtype=np.intp)
        # p as Python floats: numpy's vectorised power may differ from libm in the last bit
        ps = np.array([10.0**log_p * problem.factorial2 for log_p in log_ps])
        values = np.empty(len(ks))
        at = np.array(log_ps)
        # the one-channel arithmetic, column by column: f = y - p (m!)^2 W^-1 Q delta
        for block in _column_blocks(len(ks)):
            scale = ps[None, block] * problem.winv[:, None]
            y = self.y[:, cols[block]]
            fitted = y - scale * _banded.q_times(problem.q, delta[:, block])
            # contiguous rows: each sum runs in the order of a one-column sum
            rss = np.ascontiguousarray((problem.w[:, None] * (y - fitted) ** 2).T).sum(axis=1)
            values[block] = _criterion(rss, rdof[block], n)
            self._keep(cols[block], values[block], at[block], fitted, rss, rdof[block])
        for i, k in enumerate(ks):
            out[k] = float(values[i])
        return out


#: Channels whose fits are computed together (bounds the (N, channels) temporaries).
COLUMN_BLOCK = 16


def _column_blocks(count: int) -> list[NDArray[np.intp]]:
    """Indices ``0 .. count - 1`` in blocks of at most :data:`COLUMN_BLOCK`."""
    return [
        np.arange(start, min(start + COLUMN_BLOCK, count), dtype=np.intp)
        for start in range(0, count, COLUMN_BLOCK)
    ]


def _step_together(
    searches: dict[int, Generator[float, float, tuple[float, float]]],
    evaluate: Callable[[dict[int, float]], dict[int, float]],
) -> dict[int, tuple[float, float]]:
    """Step the searches side by side, evaluating their points in batches.

    Each search yields one point at a time and is sent its criterion value; a
    round evaluates the pending points of every unfinished search in one call to
    ``evaluate``. Returns each search's result (its generator's return value).
    """
    results: dict[int, tuple[float, float]] = {}
    pending: dict[int, float] = {}
    for k, search in searches.items():
        pending[k] = float(next(search))
    while pending:
        values = evaluate(pending)
        ahead: dict[int, float] = {}
        for k in pending:
            try:
                ahead[k] = float(searches[k].send(values[k]))
            except StopIteration as done:
                results[k] = done.value
        pending = ahead
    return results


class _Aborted(Exception):
    """Raised in a lockstep task when the batch evaluation failed."""


def gcv_fit_many(
    problem: PenalisedSpline, y: FloatArray, step: float = 2.0, x: FloatArray | None = None
) -> tuple[FloatArray, FloatArray, list[FitStatistics]]:
    """Smoothing parameters minimising GCV for every channel of y (N, K), with their fits.

    Returns p (K,), the fitted values (N, K) and the figures of each channel's
    fit. The search of each channel is :func:`~spotlab.kinematics.gcv.gcv_fit`'s;
    records longer than :data:`~spotlab.kinematics.gcv.LONG_RECORD` (given ``x``)
    are searched channel by channel, as there.
    """
    k_all = y.shape[1]
    if x is not None and problem.n_eff > LONG_RECORD:
        ps, cols, stats = [], [], []
        for k in range(k_all):
            pk, fitted, st = gcv_fit(problem, y[:, k : k + 1], step, x)
            ps.append(pk)
            cols.append(fitted[:, 0])
            stats.append(st)
        return np.array(ps), np.stack(cols, axis=1), stats
    if problem.kernel is not None:
        return search_native(problem, y, step)
    channels = _Channels(problem, y)
    lo, hi = problem.log_p_range
    grid = np.arange(lo, hi + step, step)
    values = channels.scan(grid)
    log_p = np.full(k_all, float(grid[-1]))
    searches: dict[int, Generator[float, float, tuple[float, float]]] = {}
    bounds: dict[int, float] = {}
    for k in range(k_all):
        if not np.any(np.isfinite(values[:, k])):
            continue
        best = int(np.argmin(values[:, k]))
        a, b = grid[max(best - 1, 0)], grid[min(best + 1, grid.size - 1)]
        log_p[k] = float(grid[best])
        searches[k] = bounded_brent(float(a), float(b), xatol=1e-6)
        bounds[k] = float(values[best, k])
    for k, (refined, value) in _step_together(searches, channels.evaluate).items():
        if value <= bounds[k]:
            log_p[k] = refined
    return _finish(channels, log_p)


def _finish(
    channels: _Channels, log_p: FloatArray
) -> tuple[FloatArray, FloatArray, list[FitStatistics]]:
    """p, fitted values and figures at each channel's chosen ``log10 p``."""
    problem, n = channels.problem, channels.problem.n_eff
    fitted = channels.best_fit
    rss, rdof = np.array(channels.best_rss), np.array(channels.best_rdof)
    redo = [k for k in range(log_p.size) if channels.best_log_p[k] != log_p[k]]
    if redo:
        chols = []
        for k in redo:
            p = 10.0 ** float(log_p[k])
            chol = np.array(problem.factor(p))
            cols, sums = _fits(
                problem, p, chol, channels.y[:, k : k + 1], channels.rhs[:, k : k + 1]
            )
            fitted[:, k], rss[k] = cols[:, 0], sums[0]
            chols.append(chol)
        rdof[redo] = _rdof(problem, chols)
    stats = []
    for k in range(log_p.size):
        msr = np.array([rss[k] / n])
        stats.append(
            FitStatistics(
                msr=msr, dof=n - rdof[k], gcv=msr / (rdof[k] / n) ** 2, variance=msr * n / rdof[k]
            )
        )
    # p as Python floats, like the one-channel search (numpy's power may differ in the last bit)
    return np.array([10.0 ** float(v) for v in log_p]), fitted, stats
