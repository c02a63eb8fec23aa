"""The natural spline through fitted values, as a callable, compiled or SciPy's.

The smoothing spline is the natural interpolant of its values at the samples: degree
``k = 2m - 1``, knots at the samples (each end ``k`` times more), derivatives
``m .. 2m - 2`` zero at both ends. With the compiled kernel (``_c_bspline.c``) it is
found and evaluated without SciPy; its twin is ``scipy.interpolate.make_interp_spline``
and ``BSpline``, imported only when the twin runs (SciPy's interpolation package is
most of a fit's memory for short records).
"""

from __future__ import annotations

from collections.abc import Callable
from types import ModuleType

import numpy as np
from numpy.typing import ArrayLike, NDArray

from spotlab.core import native

FloatArray = NDArray[np.float64]

#: The compiled kernel; without it SciPy's interpolation is its twin.
KERNEL = "spotlab.kinematics._c_bspline"

#: A spline: values or the nu-th derivative at points (any shape), shape (..., K).
Spline = Callable[..., FloatArray]


class _KernelSpline:
    """B-spline of degree k with knots t and coefficients c (n + k - 1, K), by the kernel."""

    def __init__(self, kernel: ModuleType, t: FloatArray, c: FloatArray, k: int) -> None:
        self._kernel, self.t, self.c, self.k = kernel, t, c, k

    def __call__(self, x: ArrayLike, nu: int = 0) -> FloatArray:
        """Values (nu = 0) or the nu-th derivative at x inside the knots' base interval.

        Parameters
        ----------
        x : array_like, any shape (...)
            Points, in the sample times' units.
        nu : int
            Derivative order, 0 .. k.

        Returns
        -------
        ndarray, shape (..., K)
        """
        xs = np.asarray(x, dtype=np.float64)
        flat = np.ascontiguousarray(xs.reshape(-1))
        nc, nch = self.c.shape
        out = np.empty((flat.size, nch))
        self._kernel.evaluate(self.t, self.c, flat, out, nc, self.k, nch, flat.size, int(nu))
        return out.reshape(*xs.shape, nch)


def natural_spline(x: FloatArray, f: FloatArray, degree: int) -> Spline:
    """The natural spline of odd ``degree`` through values f (N, K) at x (N,).

    Parameters
    ----------
    x : ndarray, shape (N,)
        Strictly increasing sample times, N > degree.
    f : ndarray, shape (N, K)
        Values at the samples.
    degree : int
        Odd degree 2m - 1 (3 or 5).

    Returns
    -------
    Spline
        Callable ``spline(points, nu=0)`` giving shape (..., K); points inside
        ``[x_0, x_{N-1}]``.
    """
    m = (degree + 1) // 2
    kernel = native.load(KERNEL)
    if kernel is None:
        from scipy.interpolate import BSpline, make_interp_spline

        ends = [(order, np.zeros(f.shape[1:])) for order in range(m, degree)]
        interp = make_interp_spline(x, f, k=degree, bc_type=(ends, ends))
        spline: Spline = BSpline.construct_fast(interp.t, interp.c, degree)
        return spline
    n, nch = f.shape
    t = np.concatenate([np.full(degree, x[0]), x, np.full(degree, x[-1])])
    c = np.empty((n + degree - 1, nch))
    kernel.natural(
        t, np.ascontiguousarray(x, dtype=np.float64), np.ascontiguousarray(f, dtype=np.float64),
        c, n, degree, nch,
    )  # fmt: skip
    return _KernelSpline(kernel, t, c, degree)
