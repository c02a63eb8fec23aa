"""Banded algebra for natural smoothing splines (Reinsch's formulation).

Everything here is O(n) in time and memory: matrices are held as their
diagonals (LAPACK upper band storage, ``ab[bw + i - j, j] = a[i, j]``) or as
per-row arrays of the few non-zero entries; nothing is N x N.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.interpolate import BSpline

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


def bspline_gram_band(x: FloatArray, m: int) -> FloatArray:
    """Gram matrix ``R_jk = integral N_j N_k`` of the order-m B-splines on knots x.

    ``N_j`` has knots ``x_j .. x_{j+m}`` and unit integral, so that
    ``f[x_j..x_{j+m}] = (1/m!) integral N_j f^(m)`` (Peano kernel). Products
    have degree 2m - 2; an m-point Gauss-Legendre rule per interval is exact.
    Returned in upper band storage of half-bandwidth m (its own is m - 1),
    shape (m + 1, N - m).
    """
    n = x.size
    rows = n - m
    nodes, weights = np.polynomial.legendre.leggauss(m)
    h = np.diff(x)
    mid = 0.5 * (x[1:] + x[:-1])
    points = (mid[:, None] + 0.5 * h[:, None] * nodes[None, :]).ravel()
    qw = (0.5 * h[:, None] * weights[None, :]).ravel()
    # m - 1 extra knots each side put every sample interval inside the base interval
    pad = np.arange(1, m)
    knots = np.concatenate([x[0] - pad[::-1] * h[0], x, x[-1] + pad * h[-1]])
    dm = BSpline.design_matrix(points, knots, m - 1).tocsr()
    if dm.nnz != m * points.size:  # pragma: no cover - scipy stores m entries per row
        raise AssertionError("unexpected design-matrix structure")
    vals = dm.data.reshape(-1, m)
    first = dm.indices.reshape(-1, m)[:, 0] - (m - 1)
    scale = np.zeros(rows + m + 1)
    scale[:rows] = m / (x[m:] - x[:rows])
    ab = np.zeros((m + 1, rows))
    for a in range(m):
        ca = first + a
        for b in range(a, m):
            cb = first + b
            ok = (ca >= 0) & (cb < rows)
            contrib = qw[ok] * vals[ok, a] * vals[ok, b] * scale[ca[ok]] * scale[cb[ok]]
            ab[m - (b - a)] += np.bincount(cb[ok], weights=contrib, minlength=rows)
    return ab


def inverse_band(chol: FloatArray) -> FloatArray:
    """Band of the inverse of a matrix from its upper banded Cholesky factor.

    Returns ``s`` with ``s[i, d] = inv(A)[i, i + d]`` for ``d = 0 .. bw``
    (zero past the end).

    Notes
    -----
    Takahashi's backward recursion (Hutchinson & de Hoog 1985): from
    ``U Sigma = U^-T``, the window ``X_i = Sigma[i:i+bw, i:i+bw]`` follows
    ``X_i = T_i X_{i+1} T_i^T + e_1 e_1^T / U_ii^2`` with ``T_i`` the
    companion matrix of row i of U, O(n bw^2) in all. The maps compose, so
    the n steps run as ~sqrt(n) blocks side by side: compose each block's
    map, chain the block maps, then run all blocks from their known ends
    together. About 3 sqrt(n) vectorised steps instead of n scalar ones.
    """
    bw = chol.shape[0] - 1
    n = chol.shape[1]
    length = max(int(np.ceil(np.sqrt(n))), 1)
    blocks = -(-n // length)
    total = blocks * length
    # past the end: no coupling and no source, so the window stays zero
    coupling = np.zeros((total, bw))
    source = np.zeros(total)
    diag = chol[bw]
    for d in range(1, bw + 1):
        coupling[: n - d, d - 1] = chol[bw - d, d:] / diag[: n - d]
    source[:n] = 1.0 / diag**2
    # block b, step j is sample b * length + j: views, no gathers, in the loops
    coupling_bj = coupling.reshape(blocks, length, bw)
    source_bj = source.reshape(blocks, length)

    def apply_t(c: FloatArray, x: FloatArray) -> FloatArray:
        # T x for a batch, T = [[-c], [I, 0]] (the companion matrix of row i of U)
        tx = np.empty_like(x)
        tx[:, 0, :] = -np.einsum("bk,bkl->bl", c, x)
        tx[:, 1:, :] = x[:, :-1, :]
        return tx

    def step(x: FloatArray, j: int) -> FloatArray:
        # T x T^T + source e1 e1^T
        c = coupling_bj[:, j]
        out = apply_t(c, apply_t(c, x).transpose(0, 2, 1))
        out[:, 0, 0] += source_bj[:, j]
        return out

    # 1. each block's map X -> phi X phi^T + psi
    phi = np.broadcast_to(np.eye(bw), (blocks, bw, bw)).copy()
    psi = np.zeros((blocks, bw, bw))
    for j in range(length - 1, -1, -1):
        phi = apply_t(coupling_bj[:, j], phi)
        psi = step(psi, j)
    # 2. the window at the end of each block
    ends = np.zeros((blocks, bw, bw))
    x = np.zeros((bw, bw))
    for b in range(blocks - 1, -1, -1):
        ends[b] = x
        x = phi[b] @ x @ phi[b].T + psi[b]
    # 3. all blocks from their ends at once
    s = np.zeros((blocks, length, bw + 1))
    x_batch = ends
    for j in range(length - 1, -1, -1):
        s[:, j, bw] = -np.einsum("bk,bk->b", coupling_bj[:, j], x_batch[:, :, bw - 1])
        x_batch = step(x_batch, j)
        s[:, j, :bw] = x_batch[:, 0, :]
    s = s.reshape(total, bw + 1)
    return s[:n]
