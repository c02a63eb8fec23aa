"""Banded algebra for natural smoothing splines (Reinsch's formulation).

Everything here is O(n) in time and memory: matrices are held as their
diagonals (LAPACK upper band storage, ``ab[bw + i - j, j] = a[i, j]``) or as
per-row arrays of the few non-zero entries; nothing is N x N.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

# the trace of the inverse has its own module; callers reach it here too
from spotlab.kinematics._takahashi import InverseTrace as InverseTrace

FloatArray = NDArray[np.float64]


def divided_differences(x: FloatArray, m: int) -> FloatArray:
    """Weights of the m-th divided differences: ``q[j, a]`` multiplies ``f[j + a]``.

    ``f[x_j, ..., x_{j+m}] = sum_a q[j, a] f_{j+a}``; shape (N - m, m + 1).
    """
    rows = x.size - m
    q = np.ones((rows, m + 1))
    for a in range(m + 1):
        for b in range(m + 1):
            if a != b:
                q[:, a] /= x[a : a + rows] - x[b : b + rows]
    return q


def qt_times(q: FloatArray, y: FloatArray) -> FloatArray:
    """``Q^T y`` for y of shape (N, K); shape (N - m, K)."""
    rows, width = q.shape
    out = np.zeros((rows, y.shape[1]))
    for a in range(width):
        out += q[:, a : a + 1] * y[a : a + rows]
    return out


def q_times(q: FloatArray, delta: FloatArray) -> FloatArray:
    """``Q delta`` for delta of shape (N - m, K); shape (N, K)."""
    rows, width = q.shape
    out = np.zeros((rows + width - 1, delta.shape[1]))
    for a in range(width):
        out[a : a + rows] += q[:, a : a + 1] * delta
    return out


def qwq_band(q: FloatArray, winv: FloatArray) -> FloatArray:
    """Upper band storage (m + 1, N - m) of ``Q^T W^-1 Q``.

    Entry (j, j + d) is ``sum_a q[j, a] q[j + d, a - d] / w[j + a]``, a = d .. m.
    """
    rows, width = q.shape
    m = width - 1
    ab = np.zeros((width, rows))
    for d in range(width):
        acc = np.zeros(rows - d)
        for a in range(d, width):
            acc += q[: rows - d, a] * q[d:, a - d] * winv[a : a + rows - d]
        ab[m - d, d:] = acc
    return ab


def _bspline_values(knots: FloatArray, t: FloatArray, degree: int) -> list[FloatArray]:
    """Values of the B-splines of a degree that are non-zero on each knot interval.

    Row i of ``t`` (shape (I, P)) holds points of knot interval ``degree + i``,
    ``knots[degree + i] <= t < knots[degree + i + 1]``. Returns ``degree + 1``
    arrays shaped like ``t``: entry a is the B-spline of index ``i + a``
    (Cox-de Boor recursion, vectorised over intervals and points).
    """
    rows = t.shape[0]

    def knot(shift: int) -> FloatArray:
        # knots[degree + i + shift] for every interval i, as a column
        return knots[degree + shift : degree + shift + rows, None]

    values = [np.ones_like(t)]
    for r in range(1, degree + 1):
        saved = np.zeros_like(t)
        nxt = []
        for s in range(r):
            right = knot(s + 1) - t
            left = t - knot(s + 1 - r)
            term = values[s] / (right + left)
            nxt.append(saved + right * term)
            saved = left * term
        nxt.append(saved)
        values = nxt
    return values


#: Sample intervals per chunk of :func:`bspline_gram_band`'s quadrature.
GRAM_CHUNK = 1 << 16


def bspline_gram_band(x: FloatArray, m: int) -> FloatArray:
    """Gram matrix ``R_jk = integral N_j N_k`` of the order-m B-splines on knots x.

    ``N_j`` has knots ``x_j .. x_{j+m}`` and unit integral, so that
    ``f[x_j..x_{j+m}] = (1/m!) integral N_j f^(m)`` (Peano kernel). Products
    have degree 2m - 2; an m-point Gauss-Legendre rule per interval is exact.
    Returned in upper band storage of half-bandwidth m (its own is m - 1),
    shape (m + 1, N - m).

    Notes
    -----
    The m B-splines alive on sample interval i are ``N_{i-m+1} .. N_i``; each
    pair's integral over the interval is a Gauss sum, and entry (j, j + d) adds
    the pairs (a, a + d) of intervals ``i = j + m - 1 - a``: shifted slices, no
    scatter.
    """
    n = x.size
    rows = n - m
    degree = m - 1
    nodes, weights = np.polynomial.legendre.leggauss(m)
    h = np.diff(x)
    # m - 1 extra knots each side put every sample interval inside the base interval
    pad = np.arange(1, m)
    knots = np.concatenate([x[0] - pad[::-1] * h[0], x, x[-1] + pad * h[-1]])
    # integral of each pair (a, b) of live B-splines over interval i, shape (N - 1,),
    # computed a chunk of intervals at a time to bound the temporaries
    pairs = {(a, b): np.empty(n - 1) for a in range(m) for b in range(a, m)}
    for start in range(0, n - 1, GRAM_CHUNK):
        stop = min(start + GRAM_CHUNK, n - 1)
        mid, half = 0.5 * (x[start + 1 : stop + 1] + x[start:stop]), 0.5 * h[start:stop]
        points = mid[:, None] + half[:, None] * nodes[None, :]  # points of interval i
        qw = half[:, None] * weights[None, :]
        values = _bspline_values(knots[start:], points, degree)
        for (a, b), out in pairs.items():
            out[start:stop] = (qw * values[a] * values[b]).sum(axis=1)
    # unit-integral scaling: N_j = m / (x_{j+m} - x_j) B_j
    scale = m / (x[m:] - x[:rows])
    ab = np.zeros((m + 1, rows))
    for (a, b), per_interval in pairs.items():
        d = b - a
        # interval i couples N_{i-m+1+a} and N_{i-m+1+b}: row j = i - m + 1 + a
        lo = m - 1 - a  # interval of row 0
        count = rows - d
        ab[m - d, d:] += per_interval[lo : lo + count]
    for d in range(m + 1):
        ab[m - d, d:] *= scale[: rows - d] * scale[d:]
    return ab
