"""Banded algebra for natural smoothing splines (Reinsch's formulation).

Everything here is O(n) in time and memory: matrices are held as their
diagonals (LAPACK upper band storage, ``ab[bw + i - j, j] = a[i, j]``) or as
per-row arrays of the few non-zero entries; nothing is N x N.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
from numpy.typing import NDArray

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


def _companion_step(
    window: FloatArray, c: FloatArray, source: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """``T X T^T + source e1 e1^T`` for stacks of symmetric windows X (bw, bw, ...).

    ``T = [[-c^T], [I, 0]]`` is the companion matrix of one row of the Cholesky
    factor; ``c`` is (bw, ...). Returns the new window, its corner (a diagonal
    entry of the inverse) and ``y = X c`` (minus the rest of that row of the inverse),
    shape (bw, ...).
    """
    bw = c.shape[0]
    y = np.add.reduce(window * c[None], axis=1)
    terms = c * y
    corner = source + terms[0]
    for a in range(1, bw):
        corner += terms[a]
    new = np.empty_like(window)
    new[1:, 1:] = window[:-1, :-1]
    rest = -y[:-1]
    new[0, 1:] = rest
    new[1:, 0] = rest
    new[0, 0] = corner
    return new, corner, y


class _BlockLayout:
    """Samples ``i = b * length + j`` as (length, ..., blocks) arrays, blocks contiguous."""

    def __init__(self, n: int) -> None:
        self.n = n
        self.length = min(max(int(np.ceil(np.sqrt(n))), 1), n)
        self.blocks = -(-n // self.length)
        self.total = self.blocks * self.length

    def arrange(self, values: FloatArray, out: FloatArray) -> FloatArray:
        """``values`` (..., n) into ``out`` (length, ..., blocks), zero past the end."""
        padded = np.zeros((*values.shape[:-1], self.total))
        padded[..., : values.shape[-1]] = values
        return self.arrange_padded(padded, out)

    def arrange_padded(self, padded: FloatArray, out: FloatArray) -> FloatArray:
        """``padded`` (..., total), zero past n, into ``out`` (length, ..., blocks)."""
        by_block = padded.reshape(*padded.shape[:-1], self.blocks, self.length)
        out[...] = np.moveaxis(by_block, -1, 0)
        return out


def _takahashi(
    chol: FloatArray, layout: _BlockLayout, coupling: FloatArray, source: FloatArray
) -> Iterator[tuple[int, FloatArray, FloatArray]]:
    """Steps of Takahashi's recursion for all blocks (and factors) at once, last sample first.

    ``chol`` is one upper banded factor (bw + 1, n) or a stack (C, bw + 1, n).
    Yields ``(j, corner, y)`` per step j of every block: ``corner`` (C, blocks) is
    ``inv(A)[i, i]`` and ``-y[k - 1]`` is ``inv(A)[i, i + k]`` for ``i = b * length + j``.
    ``coupling`` (bw, length, C, blocks) and ``source`` (length, C, blocks) are work arrays.

    Notes
    -----
    Takahashi's backward recursion (Hutchinson & de Hoog 1985): from
    ``U Sigma = U^-T``, the window ``X_i = Sigma[i:i+bw, i:i+bw]`` follows
    ``X_i = T_i X_{i+1} T_i^T + e_1 e_1^T / U_ii^2`` with ``T_i`` the
    companion matrix of row i of U, O(n bw^2) in all. The maps compose, so
    the n steps run as blocks side by side: compose each block's map, chain
    the block maps, then run all blocks from their known ends together. The
    windows are held entry by entry (arrays over factors and blocks), so each
    step is a few dozen vector operations whatever the number of factors.
    """
    stack = chol if chol.ndim == 3 else chol[None]
    count, bands, n = stack.shape
    bw = bands - 1
    blocks, length = layout.blocks, layout.length
    diag = stack[:, bw]
    # past the end: no coupling and no source, so the window stays zero
    row = np.zeros((count, layout.total))
    for d in range(1, bw + 1):
        np.divide(stack[:, bw - d, d:], diag[:, : n - d], out=row[:, : n - d])
        row[:, n - d :] = 0.0
        layout.arrange_padded(row, coupling[d - 1])
    np.square(diag, out=row[:, :n])
    np.divide(1.0, row[:, :n], out=row[:, :n])
    layout.arrange_padded(row, source)
    # 1. each block's map X -> phi X phi^T + psi, as stacks (bw, bw, C, blocks)
    phi = np.zeros((bw, bw, count, blocks))
    for a in range(bw):
        phi[a, a] = 1.0
    psi = np.zeros((bw, bw, count, blocks))
    for j in range(length - 1, -1, -1):
        c = coupling[:, j]
        top = np.negative(np.add.reduce(phi * c[:, None], axis=0))
        phi = np.concatenate([top[None], phi[:-1]])
        psi, _, _ = _companion_step(psi, c, source[j])
    # (C, blocks, bw, bw)
    phi_b: FloatArray = np.moveaxis(phi, (2, 3), (0, 1))
    psi_b: FloatArray = np.moveaxis(psi, (2, 3), (0, 1))
    # 2. the window at the end of each block
    ends = np.zeros((count, blocks, bw, bw))
    x = np.zeros((count, bw, bw))
    phi_t = np.swapaxes(phi_b, 2, 3)
    for b in range(blocks - 1, -1, -1):
        ends[:, b] = x
        x = phi_b[:, b] @ x @ phi_t[:, b] + psi_b[:, b]
    # 3. all blocks from their ends at once
    window = np.ascontiguousarray(np.moveaxis(ends, (2, 3), (0, 1)))
    for j in range(length - 1, -1, -1):
        window, corner, y = _companion_step(window, coupling[:, j], source[j])
        yield j, corner, y


class InverseTrace:
    """``tr(inv(A) R)`` for banded A (from its Cholesky factor) and a fixed banded R.

    Parameters
    ----------
    r : ndarray, shape (bw + 1, n)
        R in upper band storage (the band of A may be as wide, not wider).

    Notes
    -----
    Only the band of ``inv(A)`` enters the trace, and its entries are summed as
    Takahashi's recursion (:func:`_takahashi`) produces them, block-major, so no
    band of the inverse is ever stored. Several factors of the same size (one
    matrix at several smoothing parameters) run side by side in one recursion,
    so its per-step cost in Python is paid once for all of them. The work arrays
    are kept between calls: a smoothing-parameter search evaluates the trace
    many times at one size.
    """

    def __init__(self, r: FloatArray) -> None:
        bw = r.shape[0] - 1
        n = r.shape[1]
        self.layout = _BlockLayout(n)
        shape = (self.layout.length, self.layout.blocks)
        # entry (i, i + d) counts twice for d > 0 (both triangles)
        self.r = np.empty((bw + 1, *shape))
        for d in range(bw + 1):
            row = np.zeros(n)
            row[: n - d] = r[bw - d, d:] * (1.0 if d == 0 else 2.0)
            self.layout.arrange(row, self.r[d])
        self._bw = bw
        self._work: dict[int, tuple[FloatArray, FloatArray]] = {}

    def _arrays(self, count: int) -> tuple[FloatArray, FloatArray]:
        if count not in self._work:
            shape = (self.layout.length, count, self.layout.blocks)
            self._work = {count: (np.empty((self._bw, *shape)), np.empty(shape))}
        return self._work[count]

    def __call__(self, chol: FloatArray) -> float:
        """The trace, for the upper banded Cholesky factor ``chol`` (bw + 1, n) of A."""
        return float(self.many(chol[None])[0])

    def many(self, chol: FloatArray) -> FloatArray:
        """The traces, shape (C,), for a stack of upper banded factors ``chol`` (C, bw + 1, n)."""
        coupling, source = self._arrays(chol.shape[0])
        acc = np.zeros((chol.shape[0], self.layout.blocks))
        for j, corner, y in _takahashi(chol, self.layout, coupling, source):
            acc += corner * self.r[0, j]
            # term by term, in this order: GCV's minimum is flat, so the searched p follows
            # the trace's last bits (the batched and one-channel searches must agree)
            for term in y * self.r[1:, j, None]:
                acc -= term
        return np.asarray(acc.sum(axis=1), dtype=np.float64)
