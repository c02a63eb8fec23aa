"""The compiled GCV kernel gives its numpy twin's figures to the last bit (issue 19).

The kernel does the twin's floating-point operations in the twin's order: LAPACK's
dpbtf2 and dpbtrs as SciPy's OpenBLAS runs them (its short axpy and dot kernels fuse
multiply and add), _takahashi's block recursion (numpy's matmul of its small stacks
fuses too) and numpy's summation orders. So the criterion at every p is bitwise the
twin's, a GCV search visits the same points and stops at the same p, and the fits
there are the twin's. Where the twin's libraries do not fuse (a processor without FMA)
the two differ by rounding only; the tests here then skip (test_spline_native checks
the agreement to 1e-9 everywhere).
"""

from __future__ import annotations

import numpy as np
import pytest
from _spline_twins import signals, twin_and_kernel

from spotlab.core import native
from spotlab.kinematics import SmoothingSpline, gcv, gcv_batch
from spotlab.kinematics.gcv import KERNEL, PenalisedSpline


def _twin_fuses() -> bool:
    """Whether the twin's dpbtrf and numpy's matmul round ``a + b c`` once (FMA)."""
    from scipy.linalg import lapack

    # A = [[1, x], [x, a]]: U[1, 1]^2 = a - x^2, x^2 = 1 + 2^-29 + 2^-60 exactly
    x = 1.0 + 2.0**-30
    a = 1.0 + 2.0**-29 + 2.0**-20
    band = np.array([[0.0, x], [1.0, a]], order="F")
    chol, info = lapack.dpbtrf(band, lower=0)
    fused_factor = info == 0 and chol[1, 1] == np.sqrt(2.0**-20 - 2.0**-60)
    # a strided (2, 2) stack, as _takahashi multiplies its block maps: -(1 + 2^-29) + x x
    left = np.zeros((2, 2, 1, 2))
    left[0, 0, 0, 0], left[0, 1, 0, 0] = -1.0, x
    right = np.zeros((1, 2, 2))
    right[0, 0, 0], right[0, 1, 0] = 1.0 + 2.0**-29, x
    out = np.matmul(np.moveaxis(left, (2, 3), (0, 1))[:, 0], right)
    return bool(fused_factor and out[0, 0, 0] == 2.0**-60)


pytestmark = [
    pytest.mark.skipif(native.load(KERNEL) is None, reason="kernel not built"),
    pytest.mark.skipif(not _twin_fuses(), reason="the twin's libraries do not fuse here"),
]


@pytest.mark.parametrize(("n", "k"), [(9, 1), (61, 3), (700, 1), (1500, 2)])
@pytest.mark.parametrize("m", [1, 2, 3, 4])
def test_the_criterion_at_any_p_is_the_twins_bitwise(
    n: int, k: int, m: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    t, y = signals(n, k, seed=10 * n + m)
    w = np.random.default_rng(n + m).uniform(0.3, 3.0, n)
    twin, kernel = twin_and_kernel(lambda: PenalisedSpline(t, w, m), monkeypatch)
    lo, hi = twin.log_p_range
    # across the whole search range, and densely where a GCV minimum lies
    log_ps = np.concatenate([np.linspace(lo, hi, 9), lo + (hi - lo) * 0.4 + 1e-6 * np.arange(4)])
    for log_p in log_ps:
        p = 10.0 ** float(log_p)
        try:
            f_twin, s_twin = twin.statistics(p, y)
        except np.linalg.LinAlgError:  # not positive definite in the twin: nor in the kernel
            with pytest.raises(np.linalg.LinAlgError):
                kernel.statistics(p, y)
            continue
        f_kernel, s_kernel = kernel.statistics(p, y)
        assert np.array_equal(f_kernel, f_twin), log_p
        assert s_kernel.dof == s_twin.dof, log_p
        for name in ("msr", "gcv", "variance"):
            assert np.array_equal(getattr(s_kernel, name), getattr(s_twin, name)), (log_p, name)


@pytest.mark.parametrize(("n", "k", "m"), [(12, 2, 1), (300, 3, 2), (97, 4, 3), (500, 3, 4)])
def test_searches_stop_at_the_twins_p(
    n: int, k: int, m: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    t, y = signals(n, k, seed=n + m)
    w = np.random.default_rng(n).uniform(0.3, 3.0, n)
    twin, kernel = twin_and_kernel(
        lambda: gcv_batch.gcv_fit_many(PenalisedSpline(t, w, m), y), monkeypatch
    )
    (p_twin, f_twin, s_twin), (p_kernel, f_kernel, s_kernel) = twin, kernel
    assert np.array_equal(p_kernel, p_twin)
    assert np.array_equal(f_kernel, f_twin)
    for a, b in zip(s_kernel, s_twin, strict=True):
        assert a.dof == b.dof and np.array_equal(a.gcv, b.gcv) and np.array_equal(a.msr, b.msr)


@pytest.mark.parametrize(("n", "degree"), [(12, 5), (700, 3), (2500, 5)])
def test_smoothing_splines_equal_the_twins(
    n: int, degree: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    t, y = signals(n, 6, seed=n + degree)
    y[n // 3 : n // 3 + n // 20 + 1, 1] = np.nan  # a gap: channel 1 alone
    y[n // 2 : n // 2 + 2, 4] = np.nan
    twin, kernel = twin_and_kernel(lambda: SmoothingSpline(t, y, degree=degree), monkeypatch)
    a, b = kernel, twin
    assert isinstance(a, SmoothingSpline) and isinstance(b, SmoothingSpline)
    for name in ("p", "gcv", "dof", "msr", "variance"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    # the fitted values are the twin's; the interpolating splines through them (_c_bspline
    # and SciPy) round differently, well below 1e-12 of the values
    ref = b(t)
    assert np.max(np.abs(a(t) - ref)) <= 1e-12 * np.max(np.abs(ref))


def test_long_record_searches_equal_the_twins(monkeypatch: pytest.MonkeyPatch) -> None:
    # the walk from a start value (fixed-p fits, one per point), made to run on a short record
    monkeypatch.setattr(gcv, "LONG_RECORD", 1000)
    monkeypatch.setattr(gcv_batch, "LONG_RECORD", 1000)
    monkeypatch.setattr(gcv, "START_SEGMENT_LENGTH", 400)
    t, y = signals(3000, 2, seed=5)
    twin, kernel = twin_and_kernel(lambda: SmoothingSpline(t, y), monkeypatch)
    assert isinstance(kernel, SmoothingSpline) and isinstance(twin, SmoothingSpline)
    for name in ("p", "gcv", "dof"):
        assert np.array_equal(getattr(kernel, name), getattr(twin, name)), name
