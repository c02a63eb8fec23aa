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
    (zero past the end). Takahashi's backward recursion (Hutchinson & de Hoog
    1985): from ``U Sigma = U^-T``, row i of Sigma inside the band needs only
    rows i+1 .. i+bw inside the band, so the cost is O(n bw^2).
    """
    bw = chol.shape[0] - 1
    n = chol.shape[1]
    # u[i, d] = U[i, i + d]
    u = np.zeros((n + bw, bw + 1))
    for d in range(bw + 1):
        u[: n - d, d] = chol[bw - d, d:]
    s = np.zeros((n + bw, bw + 1))
    window = np.zeros((bw, bw))  # Sigma[i+1 .. i+bw, i+1 .. i+bw]
    diag = u[:n, 0]
    coupling = u[:n, 1:] / diag[:, None]
    for i in range(n - 1, -1, -1):
        c = coupling[i]
        row = -(c @ window)
        sii = 1.0 / diag[i] ** 2 - c @ row
        s[i, 0] = sii
        s[i, 1:] = row
        window[1:, 1:] = window[:-1, :-1]
        window[0, 1:] = row[:-1]
        window[1:, 0] = row[:-1]
        window[0, 0] = sii
    return s[:n]


def residual_hat_diagonal(q: FloatArray, winv: FloatArray, band: FloatArray) -> FloatArray:
    """Diagonal of ``W^-1 Q Sigma Q^T`` from the band of Sigma; shape (N,).

    ``band[j, d] = Sigma[j, j + d]`` (from :func:`inverse_band`); sample i
    enters the divided differences j = i - m .. i as ``q[j, i - j]``.
    """
    rows, width = q.shape
    n = rows + width - 1
    out = np.zeros(n)
    for a1 in range(width):
        for a2 in range(width):
            # samples i with j1 = i - a1 and j2 = i - a2 both in 0 .. rows - 1
            lo, hi = max(a1, a2), min(rows + a1, rows + a2)
            i = np.arange(lo, hi)
            j1, j2 = i - a1, i - a2
            out[lo:hi] += q[j1, a1] * q[j2, a2] * band[np.minimum(j1, j2), abs(a1 - a2)]
    return winv * out
