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
  lockstep: each channel's :func:`scipy.optimize.minimize_scalar` runs in its own
  thread and waits for its criterion value, and each round factors the
  channels' matrices and computes all their traces in one recursion.
"""

from __future__ import annotations

import threading
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray
from scipy import linalg, optimize
from scipy.linalg import lapack

from spotlab.kinematics import _banded
from spotlab.kinematics.gcv import LONG_RECORD, FitStatistics, PenalisedSpline, gcv_fit

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
    delta, info = lapack.dpbtrs(chol, rhs, lower=0)
    if info != 0:  # pragma: no cover - dpbtrs fails only on bad arguments
        raise linalg.LinAlgError(f"banded solve failed (info {info})")
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
        log_p: float,
        fit: FloatArray,
        rss: FloatArray,
        rdof: float,
    ) -> None:
        """Remember the fits of channels ``cols`` (fit (N, len(cols))) that beat their best."""
        better = values < self.best_value[cols]
        if np.any(better):
            chosen = cols[better]
            self.best_value[chosen], self.best_log_p[chosen] = values[better], log_p
            self.best_fit[:, chosen] = fit[:, better]
            self.best_rss[chosen], self.best_rdof[chosen] = rss[better], rdof

    def scan(self, grid: FloatArray) -> FloatArray:
        """Criterion of every channel at every grid point, shape (G, K)."""
        problem, n = self.problem, self.problem.n_eff
        values = np.full((grid.size, self.y.shape[1]), np.inf)
        chols, rows = [], []
        for g, log_p in enumerate(grid):
            try:
                chols.append(np.array(problem.factor(10.0 ** float(log_p))))
            except linalg.LinAlgError:
                continue
            rows.append(g)
        if not chols:
            return values
        everyone = np.arange(self.y.shape[1], dtype=np.intp)
        # traces first (one recursion for all grid points), then one grid point's fits at a time
        for g, r, chol in zip(rows, _rdof(problem, chols), chols, strict=True):
            fitted, rss = _fits(problem, 10.0 ** float(grid[g]), chol, self.y, self.rhs)
            values[g] = _criterion(rss, np.full(rss.shape, r), n)
            self._keep(everyone, values[g], float(grid[g]), fitted, rss, float(r))
        return values

    def evaluate(self, points: dict[int, float]) -> dict[int, float]:
        """Criterion of channel k at ``log10 p = points[k]``, each at its own p."""
        problem, n = self.problem, self.problem.n_eff
        out = dict.fromkeys(points, float(np.inf))
        stack = np.empty((len(points), *problem.r.shape))
        delta = np.empty((problem.r.shape[1], len(points)))
        ks: list[int] = []
        log_ps: list[float] = []
        # channels asking for the same p (the first Brent point of a shared bracket) share
        # its factor and trace
        factor_of: dict[float, int] = {}
        which: list[int] = []
        for k, log_p in points.items():
            if log_p not in factor_of:
                try:
                    stack[len(factor_of)] = problem.factor(10.0**log_p)
                except linalg.LinAlgError:
                    continue
                factor_of[log_p] = len(factor_of)
            chol = stack[factor_of[log_p]]
            solved, info = lapack.dpbtrs(chol, self.rhs[:, k : k + 1], lower=0)
            if info != 0:  # pragma: no cover - dpbtrs fails only on bad arguments
                raise linalg.LinAlgError(f"banded solve failed (info {info})")
            delta[:, len(ks)] = solved[:, 0]
            which.append(factor_of[log_p])
            ks.append(k)
            log_ps.append(log_p)
        if not ks:
            return out
        count = len(ks)
        cols = np.array(ks, dtype=np.intp)
        # the one-channel arithmetic, column by column: f = y - p (m!)^2 W^-1 Q delta
        # p as Python floats: numpy's vectorised power may differ from libm in the last bit
        ps = np.array([10.0**log_p * problem.factorial2 for log_p in log_ps])
        scale = ps[None, :] * problem.winv[:, None]
        y = self.y[:, cols]
        fitted = y - scale * _banded.q_times(problem.q, delta[:, :count])
        # contiguous rows: each sum runs in the order of a one-column sum
        rss = np.ascontiguousarray((problem.w[:, None] * (y - fitted) ** 2).T).sum(axis=1)
        rdof = _rdof(problem, stack[: len(factor_of)])[which]
        values = _criterion(rss, rdof, n)
        for i, k in enumerate(ks):
            out[k] = float(values[i])
            self._keep(cols[i : i + 1], values[i : i + 1], log_ps[i], fitted[:, i : i + 1],
                       rss[i : i + 1], float(rdof[i]))  # fmt: skip
        return out


def _lockstep(
    tasks: dict[int, Callable[[Callable[[float], float]], float]],
    evaluate: Callable[[dict[int, float]], dict[int, float]],
) -> dict[int, float]:
    """Run ``tasks[k](criterion)`` side by side, evaluating their criteria in batches.

    Each task runs in its own thread and calls its criterion with one point at a
    time; a round starts when every unfinished task waits for a value, and
    evaluates all their points in one call to ``evaluate``.
    """
    if len(tasks) == 1:  # nothing to run side by side
        ((k, task),) = tasks.items()
        return {k: task(lambda log_p: evaluate({k: float(log_p)})[k])}
    cond = threading.Condition()
    pending: dict[int, float] = {}
    answers: dict[int, float] = {}
    ready = {k: threading.Event() for k in tasks}
    active = set(tasks)
    results: dict[int, float] = {}
    errors: list[BaseException] = []
    aborted = threading.Event()

    def criterion_of(k: int) -> Callable[[float], float]:
        def criterion(log_p: float) -> float:
            with cond:
                pending[k] = float(log_p)
                if len(pending) >= len(active):
                    cond.notify()
            ready[k].wait()
            ready[k].clear()
            if aborted.is_set():
                raise _Aborted
            return answers.pop(k)

        return criterion

    def run(k: int) -> None:
        try:
            results[k] = tasks[k](criterion_of(k))
        except _Aborted:
            pass
        except BaseException as exc:  # handed to the caller below
            errors.append(exc)
        finally:
            with cond:
                active.discard(k)
                cond.notify()

    threads = [threading.Thread(target=run, args=(k,), daemon=True) for k in tasks]
    for thread in threads:
        thread.start()
    try:
        while True:
            with cond:
                while active and len(pending) < len(active):
                    cond.wait()
                if not active:
                    break
                batch = dict(pending)
                pending.clear()
            answers.update(evaluate(batch))
            for k in batch:
                ready[k].set()
    except BaseException:
        aborted.set()  # every waiting task stops at its next criterion call
        for event in ready.values():
            event.set()
        raise
    finally:
        for thread in threads:
            thread.join()
    if errors:
        raise errors[0]
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
    channels = _Channels(problem, y)
    lo, hi = problem.log_p_range
    grid = np.arange(lo, hi + step, step)
    values = channels.scan(grid)
    log_p = np.full(k_all, float(grid[-1]))
    tasks: dict[int, Callable[[Callable[[float], float]], float]] = {}
    for k in range(k_all):
        if not np.any(np.isfinite(values[:, k])):
            continue
        best = int(np.argmin(values[:, k]))
        a, b = grid[max(best - 1, 0)], grid[min(best + 1, grid.size - 1)]
        log_p[k] = float(grid[best])

        def refine(
            criterion: Callable[[float], float],
            a: float = a,
            b: float = b,
            bound: float = values[best, k],
        ) -> float:
            res = optimize.minimize_scalar(
                criterion, bounds=(a, b), method="bounded", options={"xatol": 1e-6}
            )
            return float(res.x) if res.fun <= bound else float("nan")

        tasks[k] = refine
    for k, refined in _lockstep(tasks, channels.evaluate).items():
        if np.isfinite(refined):
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
