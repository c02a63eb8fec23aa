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

import numpy as np
import numpy.typing as npt
from scipy.linalg import solve_banded

from spotlab.acquisition.synchroniser.gaps import valid_runs

F64 = npt.NDArray[np.float64]
B = npt.NDArray[np.bool_]

#: Unknowns per banded solve (bounds the work memory to a few tens of MB).
_CHUNK = 1 << 20


def run_nodes(usable: B) -> npt.NDArray[np.int64]:
    """Samples in the run each usable interval belongs to, 0 for unusable ones.

    ``usable`` and the result have shape (C, F - 1): channels along the first axis.
    """
    c, n = usable.shape
    out = np.zeros((c, n), dtype=np.int64)
    runs = valid_runs(usable.T)
    if runs.size:
        lengths = runs[:, 2] - runs[:, 1]
        flat_start = runs[:, 0] * n + runs[:, 1]
        idx = np.repeat(flat_start - np.cumsum(np.r_[0, lengths[:-1]]), lengths) + np.arange(
            lengths.sum()
        )
        out.ravel()[idx] = np.repeat(lengths + 1, lengths)
    return out


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
    h = np.diff(x)
    # Channel-major (C, F): each channel's equations are consecutive rows of one system.
    ok = np.ascontiguousarray(usable.T)
    d = np.where(ok, np.diff(np.where(np.isfinite(y), y, 0.0).T, axis=1) / h, 0.0)
    nodes = run_nodes(ok)
    diag = np.ones((c, f))
    upper = np.zeros((c, f))  # coefficient of s_{i+1} in row i
    lower = np.zeros((c, f))  # coefficient of s_{i-1} in row i
    rhs = np.zeros((c, f))

    # Inside a run (samples 1 .. F-2 with both intervals usable): most rows.
    inner = ok[:, :-1] & ok[:, 1:]
    hm, hp = h[:-1], h[1:]  # h_{i-1}, h_i
    diag[:, 1:-1] = np.where(inner, 2.0 * (hm + hp), 1.0)
    upper[:, 1:-1] = np.where(inner, hm, 0.0)
    lower[:, 1:-1] = np.where(inner, hp, 0.0)
    rhs[:, 1:-1] = np.where(inner, 3.0 * (hp * d[:, :-1] + hm * d[:, 1:]), 0.0)

    # First sample of each run: interval i usable, interval i - 1 not.
    before = np.zeros_like(ok)
    before[:, 1:] = ok[:, :-1]
    ch, i = np.nonzero(ok & ~before)
    n_run = nodes[ch, i]
    j = np.minimum(i + 1, f - 2)
    h0, h1, d0, d1 = h[i], h[j], d[ch, i], d[ch, j]
    cases = [n_run == 2, n_run == 3]
    s = h0 + h1
    diag[ch, i] = np.select(cases, [2.0, 1.0], h1)
    upper[ch, i] = np.select(cases, [1.0, 0.0], s)
    rhs[ch, i] = np.select(
        cases,
        [3.0 * d0, d0 - (d1 - d0) * h0 / s],
        ((h0 + 2.0 * s) * h1 * d0 + h0**2 * d1) / s,
    )

    # Last sample of each run: sample k + 1 after its last usable interval k.
    after = np.zeros_like(ok)
    after[:, :-1] = ok[:, 1:]
    ch, k = np.nonzero(ok & ~after)
    n_run = nodes[ch, k]
    j = np.maximum(k - 1, 0)
    ha, hb, da, db = h[k], h[j], d[ch, k], d[ch, j]  # h_{e-1}, h_{e-2}, d_{e-1}, d_{e-2}
    cases = [n_run == 2, n_run == 3]
    s = ha + hb
    lower[ch, k + 1] = np.select(cases, [1.0, 0.0], s)
    diag[ch, k + 1] = np.select(cases, [2.0, 1.0], hb)
    rhs[ch, k + 1] = np.select(
        cases,
        [3.0 * da, da + (da - db) * ha / s],
        (ha**2 * db + (2.0 * s + ha) * hb * da) / s,
    )

    out = np.empty((c, f))
    step = max(1, _CHUNK // f)
    for c0 in range(0, c, step):
        c1 = min(c, c0 + step)
        n = (c1 - c0) * f
        ab = np.zeros((3, n))
        ab[0, 1:] = upper[c0:c1].ravel()[:-1]
        ab[1] = diag[c0:c1].ravel()
        ab[2, :-1] = lower[c0:c1].ravel()[1:]
        out[c0:c1] = solve_banded((1, 1), ab, rhs[c0:c1].ravel()).reshape(c1 - c0, f)
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
