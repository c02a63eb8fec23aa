"""The compiled GCV kernel (_c_gcv.c) against its numpy twin and against dense algebra.

The tolerances here hold on any machine: at a given p the two agree to 1e-9 relative,
and searches end at points of equal GCV (to 1e-9). Where the twin's BLAS and numpy
fuse multiply-adds (FMA processors, the usual case) the kernel is the twin to the last
bit and the searches stop at the same p (test_spline_bitwise); elsewhere the two round
differently by ~1e-13, and on the flat GCV minimum the p found may then differ by up to
~1e-5 relative, with values and figures differing accordingly (the tolerances below).
"""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest
from _spline_twins import signals, twin_and_kernel

from spotlab.core import native
from spotlab.kinematics import SmoothingSpline, gcv, gcv_batch
from spotlab.kinematics.gcv import KERNEL, FitStatistics, PenalisedSpline

REL = 1e-9


pytestmark = pytest.mark.skipif(native.load(KERNEL) is None, reason="kernel not built")


def _rel(a: object, b: object) -> float:
    a_, b_ = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return float(np.max(np.abs(a_ - b_) / np.abs(b_)))


def _value_rel(a: SmoothingSpline, b: SmoothingSpline, t: np.ndarray, nu: int = 0) -> float:
    ref = b(t, nu=nu)
    return float(np.max(np.abs(a(t, nu=nu) - ref)) / np.max(np.abs(ref)))


@pytest.mark.parametrize("m", [1, 2, 3, 4])
def test_bands_equal_the_twins_bitwise(m: int, monkeypatch: pytest.MonkeyPatch) -> None:
    rng = np.random.default_rng(m)
    x = np.cumsum(rng.uniform(0.5, 1.5, 97))
    w = rng.uniform(0.5, 2.0, x.size)
    twin, kernel = twin_and_kernel(lambda: PenalisedSpline(x, w, m), monkeypatch)
    for name in ("q", "r", "qwq"):
        assert np.array_equal(getattr(twin, name), getattr(kernel, name)), name
    assert kernel.r.flags.f_contiguous and kernel.r.shape == (m + 1, x.size - m)


# m = 4 (degree 7) is ill-conditioned beyond light smoothing: at p = 1e-8 both paths are
# 1e-9 .. 1e-8 off the exact figures (50-digit decimal arithmetic), at 1e-5 1e-7 .. 1e-6
@pytest.mark.parametrize(
    ("n", "m", "ps"),
    [
        (7, 3, (1e-12, 1e-8, 1e-5)),
        (40, 1, (1e-12, 1e-8, 1e-5)),
        (60, 2, (1e-12, 1e-8, 1e-5)),
        (300, 3, (1e-12, 1e-8, 1e-5)),
        (200, 4, (1e-14, 1e-12)),
    ],
)
def test_fits_at_one_p_equal_the_twins(
    n: int, m: int, ps: tuple[float, ...], monkeypatch: pytest.MonkeyPatch
) -> None:
    t, y = signals(n, 3, seed=n)
    w = np.random.default_rng(n).uniform(0.3, 3.0, n)
    for p in ps:

        def make(p: float = p) -> tuple[np.ndarray, FitStatistics]:
            return PenalisedSpline(t, w, m).statistics(p, y)

        twin, kernel = twin_and_kernel(make, monkeypatch)
        (f_twin, s_twin), (f_kernel, s_kernel) = twin, kernel
        scale = np.max(np.abs(f_twin), axis=0)
        assert np.all(np.max(np.abs(f_kernel - f_twin), axis=0) <= REL * scale), p
        for name in ("msr", "gcv", "variance", "dof"):
            assert _rel(getattr(s_kernel, name), getattr(s_twin, name)) <= REL, (p, name)


def test_trace_equals_the_dense_inverse() -> None:
    t, y = signals(120, 1, seed=3)
    problem = PenalisedSpline(t, np.ones(t.size), 3)
    for p in (1e-10, 1e-6):
        _, _, rdof = problem.fit(p, y)
        rows = problem.r.shape[1]
        dense_r, dense_a = np.zeros((rows, rows)), np.zeros((rows, rows))
        band_a = problem.qwq * (p * problem.factorial2) + problem.r
        for d in range(4):
            idx = np.arange(rows - d)
            for dense, band in ((dense_r, problem.r), (dense_a, band_a)):
                dense[idx, idx + d] = dense[idx + d, idx] = band[3 - d, d:]
        expected = rows - np.trace(np.linalg.solve(dense_a, dense_r))
        assert rdof == pytest.approx(expected, rel=1e-9)


@pytest.mark.parametrize(("n", "degree"), [(12, 5), (700, 5), (700, 3), (2500, 5)])
def test_gcv_searches_end_at_the_same_minimum(
    n: int, degree: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    t, y = signals(n, 4, seed=n + degree)
    y[n // 3 : n // 3 + n // 20, 1] = np.nan  # a gap: channel 1 alone
    twin, kernel = twin_and_kernel(lambda: SmoothingSpline(t, y, degree=degree), monkeypatch)
    a, b = kernel, twin
    assert isinstance(a, SmoothingSpline) and isinstance(b, SmoothingSpline)
    assert _rel(a.gcv, b.gcv) <= REL
    assert _rel(a.p, b.p) <= 1e-4
    assert _rel(a.dof, b.dof) <= 1e-5
    assert _rel(a.msr, b.msr) <= 1e-5 and _rel(a.variance, b.variance) <= 1e-5
    assert _value_rel(a, b, t) <= 1e-6
    assert _value_rel(a, b, t, nu=2) <= 1e-4


def test_one_channel_search_equals_the_batched_one() -> None:
    t, y = signals(500, 3, seed=8)
    problem = PenalisedSpline(t, np.ones(t.size), 3)
    ps, fitted, stats = gcv_batch.gcv_fit_many(problem, y, x=t)
    for j in range(3):
        p, one, st = gcv.gcv_fit(problem, y[:, j : j + 1], x=t)
        assert p == ps[j] and np.array_equal(one[:, 0], fitted[:, j])
        assert st.dof == stats[j].dof and st.gcv[0] == stats[j].gcv[0]


def test_fixed_p_and_wood_jennings_equal_the_twins(monkeypatch: pytest.MonkeyPatch) -> None:
    t, y = signals(400, 3, seed=11)
    y[50:60, 2] = np.nan
    sigma = np.full(t.size, 0.05)
    cases: list[dict[str, float | np.ndarray]] = [
        {"p": 1e-7},
        {"p": 1e-7, "sigma": sigma},
        {"degree": 3, "p": 1e-5},
    ]
    for kwargs in cases:

        def make(kw: dict[str, float | np.ndarray] = kwargs) -> SmoothingSpline:
            return SmoothingSpline(t, y, **kw)  # type: ignore[arg-type]

        twin, kernel = twin_and_kernel(make, monkeypatch)
        a, b = kernel, twin
        assert isinstance(a, SmoothingSpline) and isinstance(b, SmoothingSpline)
        for name in ("p", "dof", "gcv", "msr", "variance"):
            assert _rel(getattr(a, name), getattr(b, name)) <= REL, (kwargs, name)
        assert _value_rel(a, b, t) <= REL
    # Wood & Jennings: the root of sum(w r^2) = N, found to the rounding of that sum
    twin, kernel = twin_and_kernel(lambda: SmoothingSpline(t, y, sigma=sigma), monkeypatch)
    a, b = kernel, twin
    assert isinstance(a, SmoothingSpline) and isinstance(b, SmoothingSpline)
    assert _rel(a.p, b.p) <= 1e-8 and _rel(a.dof, b.dof) <= 1e-7
    assert _value_rel(a, b, t) <= 1e-8


def test_long_record_search_equals_the_twins(monkeypatch: pytest.MonkeyPatch) -> None:
    # the walk from a start value, made to run on a short record
    monkeypatch.setattr(gcv, "LONG_RECORD", 1000)
    monkeypatch.setattr(gcv_batch, "LONG_RECORD", 1000)
    monkeypatch.setattr(gcv, "START_SEGMENT_LENGTH", 400)
    t, y = signals(3000, 2, seed=5)
    twin, kernel = twin_and_kernel(lambda: SmoothingSpline(t, y), monkeypatch)
    a, b = kernel, twin
    assert isinstance(a, SmoothingSpline) and isinstance(b, SmoothingSpline)
    assert _rel(a.gcv, b.gcv) <= REL
    assert _rel(a.p, b.p) <= 1e-3
    assert _value_rel(a, b, t) <= 1e-5


def test_bad_arrays_raise_value_errors() -> None:
    kernel = native.load(KERNEL)
    assert kernel is not None
    t, y = signals(50, 1, seed=1)
    problem = PenalisedSpline(t, np.ones(t.size), 3)
    arrays = problem.kernel_arrays()
    fitted, rss = np.empty_like(y), np.empty(1)
    with pytest.raises(ValueError, match="y"):
        kernel.fit(*arrays, y[:-1], fitted, rss, 3, 50, 1, 1e-6, 36.0, True)
    with pytest.raises(ValueError, match="fitted"):
        kernel.fit(*arrays, y, fitted.astype(np.float32), rss, 3, 50, 1, 1e-6, 36.0, True)
    with pytest.raises(ValueError, match="m <= 8"):
        kernel.fit(*arrays, y, fitted, rss, 0, 50, 1, 1e-6, 36.0, True)
    with pytest.raises(TypeError):
        kernel.fit(*arrays, y, y.T.tolist(), rss, 3, 50, 1, 1e-6, 36.0, True)


def test_the_kernel_lets_other_threads_run() -> None:
    """While one thread is in a long kernel call, another keeps running (GIL released).

    Counted, not timed: this thread ticks while the other is inside its call (between
    the instants taken just before and just after it). Holding the interpreter lock for
    the whole call, the kernel would leave no tick inside; on a busy machine there are
    fewer, but not none.
    """
    t, y = signals(50_000, 1, seed=2)
    problem = PenalisedSpline(t, np.ones(t.size), 3)
    call: list[float] = []

    def work() -> None:
        call.append(time.perf_counter())
        gcv.gcv_fit(problem, y)  # one kernel call: the whole search (~0.1 s)
        call.append(time.perf_counter())

    worker = threading.Thread(target=work)
    ticks = []
    worker.start()
    while worker.is_alive():
        time.sleep(0.001)
        ticks.append(time.perf_counter())
    worker.join()
    inside = [tick for tick in ticks if call[0] < tick < call[1]]
    assert len(inside) >= 3, (len(inside), len(ticks), call[1] - call[0])


@pytest.mark.parametrize(("n", "k", "degree"), [(6, 1, 5), (4, 2, 3), (500, 3, 5), (300, 2, 3)])
def test_natural_spline_equals_scipys(
    n: int, k: int, degree: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    from spotlab.kinematics._natural import natural_spline

    t, y = signals(n, k, seed=n + k)
    points = np.sort(np.concatenate([t, np.random.default_rng(n).uniform(t[0], t[-1], 200)]))
    twin, kernel = twin_and_kernel(lambda: natural_spline(t, y, degree), monkeypatch)
    for nu in range(4):
        ref = twin(points, nu=nu)
        assert np.max(np.abs(kernel(points, nu=nu) - ref)) <= 1e-12 * np.max(np.abs(ref)), nu
    # a scalar point gives one value per channel; a grid keeps its shape
    assert kernel(t[-1], nu=1).shape == (k,)
    assert np.allclose(kernel(t[-1], nu=1), twin(t[-1], nu=1), rtol=1e-12, atol=0.0)
    assert kernel(points[:12].reshape(3, 4)).shape == (3, 4, k)
    # the natural end conditions: derivatives m .. 2m - 2 vanish at both ends
    m = (degree + 1) // 2
    for order in range(m, degree):
        inside = np.max(np.abs(kernel(points, nu=order)))
        ends = kernel(np.array([t[0], t[-1]]), nu=order)
        assert np.all(np.abs(ends) <= 1e-9 * inside), order
