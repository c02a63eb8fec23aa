"""Cubic interpolating splines of many channels at once, each broken at its own gaps.

Every channel (a marker's value in one sensor) shares the frame times ``x`` (F,) but has
its own usable intervals; each run of usable intervals gets its own cubic spline
(not-a-knot ends for 4 or more samples, the parabola through 3, the line through 2). The
spline is held in Hermite form, values and slopes at the samples; the slopes of all
channels solve one tridiagonal system (channel after channel, decoupled at run ends),
solved by LAPACK's banded solver in O(F C).

Slope equations (``h_i = x_{i+1} - x_i``, ``d_i`` the divided difference of interval i):

* inside a run: ``h_i s_{i-1} + 2 (h_{i-1} + h_i) s_i + h_{i-1} s_{i+1} = 3 (h_i d_{i-1} +
  h_{i-1} d_i)`` (continuous second derivative);
* first sample of a run of 4 or more (not-a-knot, continuous third derivative at the
  second sample): ``h_1 s_0 + (h_0 + h_1) s_1 = ((h_0 + 2 (h_0 + h_1)) h_1 d_0 + h_0^2 d_1)
  / (h_0 + h_1)``, and its mirror image at the last sample;
* run of 3: the parabola's end slopes ``s_0 = d_0 - (d_1 - d_0) h_0 / (h_0 + h_1)``;
* run of 2: ``2 s_0 + s_1 = 3 d_0`` at both ends, so ``s_0 = s_1 = d_0``;
* a sample in no run: ``s = 0``.

These are the standard cubic-spline slope equations (de Boor, A Practical Guide to
Splines, ch. IV), written here for runs that start and stop anywhere.
"""

from __future__ import annotations

from typing import Any, TypeVar

import numpy as np
import numpy.typing as npt
from scipy.linalg import solve_banded

from spotlab.acquisition.synchroniser.gaps import valid_runs

F64 = npt.NDArray[np.float64]
B = npt.NDArray[np.bool_]

_A = TypeVar("_A", bound=npt.NDArray[Any])

#: Unknowns per banded solve (bounds the work memory to a few tens of MB).
_CHUNK = 1 << 20


def _shift(a: _A, k: int, fill: float) -> _A:
    """``a`` moved by ``k`` rows (``out[i] = a[i - k]``), ``fill`` where nothing moved in."""
    out = np.full_like(a, fill)
    if k > 0:
        out[k:] = a[:-k]
    elif k < 0:
        out[:k] = a[-k:]
    else:
        out[:] = a
    return out


def run_nodes(usable: B) -> npt.NDArray[np.int64]:
    """Samples in the run each usable interval belongs to, 0 for unusable ones (F - 1, C)."""
    n, c = usable.shape
    out = np.zeros((c, n), dtype=np.int64)
    runs = valid_runs(usable)
    if runs.size:
        lengths = runs[:, 2] - runs[:, 1]
        flat_start = runs[:, 0] * n + runs[:, 1]
        idx = np.repeat(flat_start - np.cumsum(np.r_[0, lengths[:-1]]), lengths) + np.arange(
            lengths.sum()
        )
        out.ravel()[idx] = np.repeat(lengths + 1, lengths)
    return out.T


def slopes(x: F64, y: F64, usable: B) -> F64:
    """Slopes at the samples of the cubic spline of every channel's runs.

    Parameters
    ----------
    x : ndarray, shape (F,)
        Strictly increasing sample times, s (F >= 2).
    y : ndarray, shape (F, C)
        Samples; values outside every run are ignored (may be NaN).
    usable : ndarray of bool, shape (F - 1, C)
        Intervals a spline may span (both samples present, no gap between).

    Returns
    -------
    ndarray, shape (F, C)
        dy/dx at each sample, 0 at samples in no run.
    """
    f, c = y.shape
    h = np.diff(x)[:, None]  # (F-1, 1)
    d = np.where(usable, np.diff(np.where(np.isfinite(y), y, 0.0), axis=0) / h, 0.0)
    nodes = run_nodes(usable)
    left = np.zeros((f, c), dtype=bool)
    right = np.zeros((f, c), dtype=bool)
    left[1:] = usable
    right[:-1] = usable
    # h_{i-2}, h_{i-1}, h_i, h_{i+1} and d likewise on the rows of the samples, (F, .).
    hp0 = np.vstack([h, [[1.0]]])
    hm2, hm1, hp1 = _shift(hp0, 2, 1.0), _shift(hp0, 1, 1.0), _shift(hp0, -1, 1.0)
    dp0 = np.vstack([d, np.zeros((1, c))])
    dm1, dp1 = _shift(dp0, 1, 0.0), _shift(dp0, -1, 0.0)
    dm2 = _shift(dm1, 1, 0.0)
    n_right = np.vstack([nodes, np.zeros((1, c), dtype=np.int64)])
    n_left = _shift(n_right, 1, 0)

    diag = np.ones((f, c))
    upper = np.zeros((f, c))  # coefficient of s_{i+1} in row i
    lower = np.zeros((f, c))  # coefficient of s_{i-1} in row i
    rhs = np.zeros((f, c))

    def put(mask: B, lo: F64 | float, di: F64 | float, up: F64 | float, b: F64) -> None:
        lower[mask] = np.broadcast_to(lo, (f, c))[mask]
        diag[mask] = np.broadcast_to(di, (f, c))[mask]
        upper[mask] = np.broadcast_to(up, (f, c))[mask]
        rhs[mask] = np.broadcast_to(b, (f, c))[mask]

    inner = left & right
    put(inner, hp0, 2.0 * (hm1 + hp0), hm1, 3.0 * (hp0 * dm1 + hm1 * dp0))
    start = right & ~left
    put(start & (n_right == 2), 0.0, 2.0, 1.0, 3.0 * dp0)
    put(start & (n_right == 3), 0.0, 1.0, 0.0, dp0 - (dp1 - dp0) * hp0 / (hp0 + hp1))
    s = hp0 + hp1
    put(
        start & (n_right >= 4),
        0.0,
        hp1,
        s,
        ((hp0 + 2.0 * s) * hp1 * dp0 + hp0**2 * dp1) / s,
    )
    end = left & ~right
    put(end & (n_left == 2), 1.0, 2.0, 0.0, 3.0 * dm1)
    put(end & (n_left == 3), 0.0, 1.0, 0.0, dm1 + (dm1 - dm2) * hm1 / (hm1 + hm2))
    s = hm1 + hm2
    put(
        end & (n_left >= 4),
        s,
        hm2,
        0.0,
        (hm1**2 * dm2 + (2.0 * s + hm1) * hm2 * dm1) / s,
    )

    out = np.empty((c, f))
    lo_t, di_t, up_t, b_t = lower.T, diag.T, upper.T, rhs.T
    step = max(1, _CHUNK // f)
    for c0 in range(0, c, step):
        c1 = min(c, c0 + step)
        n = (c1 - c0) * f
        ab = np.zeros((3, n))
        ab[0, 1:] = up_t[c0:c1].ravel()[:-1]
        ab[1] = di_t[c0:c1].ravel()
        ab[2, :-1] = lo_t[c0:c1].ravel()[1:]
        out[c0:c1] = solve_banded((1, 1), ab, b_t[c0:c1].ravel()).reshape(c1 - c0, f)
    return out.T


def hermite(y0: F64, y1: F64, s0: F64, s1: F64, h: F64, w: F64) -> F64:
    """Cubic Hermite interpolation at ``x_i + w h`` from end values and slopes (broadcast)."""
    w2 = w * w
    w3 = w2 * w
    return (
        (2.0 * w3 - 3.0 * w2 + 1.0) * y0
        + (w3 - 2.0 * w2 + w) * h * s0
        + (3.0 * w2 - 2.0 * w3) * y1
        + (w3 - w2) * h * s1
    )
