"""Banded algebra for natural smoothing splines (Reinsch's formulation).

Everything here is O(n) in time and memory: matrices are held as their
diagonals (LAPACK upper band storage, ``ab[bw + i - j, j] = a[i, j]``) or as
sparse matrices with a fixed number of entries per row; nothing is N x N.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy import sparse
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


def divided_difference_matrix(q: FloatArray, n: int) -> sparse.csr_matrix:
    """The sparse (N - m) x N matrix ``Q^T`` of :func:`divided_differences`."""
    rows, width = q.shape
    j = np.repeat(np.arange(rows), width)
    i = (np.arange(rows)[:, None] + np.arange(width)[None, :]).ravel()
    return sparse.csr_matrix((q.ravel(), (j, i)), shape=(rows, n))


def bspline_gram(x: FloatArray, m: int) -> sparse.csr_matrix:
    """Gram matrix ``R_jk = integral N_j N_k`` of the order-m B-splines on knots x.

    ``N_j`` has knots ``x_j .. x_{j+m}`` and unit integral, so that
    ``f[x_j..x_{j+m}] = (1/m!) integral N_j f^(m)`` (Peano kernel). Products
    have degree 2m - 2; an m-point Gauss-Legendre rule per interval is exact.
    Shape (N - m, N - m), half-bandwidth m - 1.
    """
    n = x.size
    nodes, weights = np.polynomial.legendre.leggauss(m)
    h = np.diff(x)
    mid = 0.5 * (x[1:] + x[:-1])
    points = (mid[:, None] + 0.5 * h[:, None] * nodes[None, :]).ravel()
    qw = (0.5 * h[:, None] * weights[None, :]).ravel()
    # m - 1 extra knots each side put every sample interval inside the base interval
    pad = np.arange(1, m)
    knots = np.concatenate([x[0] - pad[::-1] * h[0], x, x[-1] + pad * h[-1]])
    phi = BSpline.design_matrix(points, knots, m - 1).tocsc()[:, m - 1 : m - 1 + n - m]
    phi = phi @ sparse.diags(m / (x[m:] - x[: n - m]))
    return (phi.T @ sparse.diags(qw) @ phi).tocsr()


def sparse_band(mat: sparse.csr_matrix, bw: int) -> FloatArray:
    """Upper band storage of a symmetric sparse matrix of half-bandwidth ``bw``."""
    n = mat.shape[0]
    ab = np.zeros((bw + 1, n))
    for d in range(bw + 1):
        ab[bw - d, d:] = mat.diagonal(d)
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
    starts = np.arange(blocks) * length

    def step(x: FloatArray, i: NDArray[np.intp]) -> FloatArray:
        # T x T^T + source e1 e1^T for a batch of windows, T = [[-c], [I, 0]]
        tx = np.empty_like(x)
        tx[:, 0, :] = -np.einsum("bk,bkl->bl", coupling[i], x)
        tx[:, 1:, :] = x[:, :-1, :]
        out = np.empty_like(x)
        out[:, :, 0] = -np.einsum("bk,bjk->bj", coupling[i], tx)
        out[:, :, 1:] = tx[:, :, :-1]
        out[:, 0, 0] += source[i]
        return out

    # 1. each block's map X -> phi X phi^T + psi
    eye = np.broadcast_to(np.eye(bw), (blocks, bw, bw))
    phi = eye.copy()
    psi = np.zeros((blocks, bw, bw))
    for j in range(length - 1, -1, -1):
        i = starts + j
        tphi = np.empty_like(phi)
        tphi[:, 0, :] = -np.einsum("bk,bkl->bl", coupling[i], phi)
        tphi[:, 1:, :] = phi[:, :-1, :]
        phi = tphi
        psi = step(psi, i)
    # 2. the window at the end of each block
    ends = np.zeros((blocks, bw, bw))
    x = np.zeros((bw, bw))
    for b in range(blocks - 1, -1, -1):
        ends[b] = x
        x = phi[b] @ x @ phi[b].T + psi[b]
    # 3. all blocks from their ends at once
    s = np.zeros((total, bw + 1))
    x_batch = ends
    for j in range(length - 1, -1, -1):
        i = starts + j
        s[i, bw] = -np.einsum("bk,bk->b", coupling[i], x_batch[:, :, bw - 1])
        x_batch = step(x_batch, i)
        s[i, :bw] = x_batch[:, 0, :]
    return s[:n]
