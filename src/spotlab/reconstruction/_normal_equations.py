"""Many small symmetric 3x3 systems solved at once in closed form.

Each point of a triangulation ends in normal equations ``A X = b`` with ``A`` symmetric
positive semi-definite (3 x 3). ``np.linalg.solve`` on a stack of 3 x 3 matrices pays a
LAPACK call per matrix; the adjugate formula below is a few dozen array operations for
the whole stack, and its intermediate quantities give the conditioning for free.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


class Normal3:
    """Accumulated normal equations of N points: the 6 entries of ``A`` and 3 of ``b``.

    Attributes
    ----------
    a : ndarray, shape (6, N)
        ``A00, A01, A02, A11, A12, A22``.
    b : ndarray, shape (3, N)
        Right-hand side.
    """

    __slots__ = ("a", "b")

    def __init__(self, n: int) -> None:
        self.a: FloatArray = np.zeros((6, n))
        self.b: FloatArray = np.zeros((3, n))

    def solve(self) -> tuple[FloatArray, FloatArray]:
        """Solve every system.

        Returns
        -------
        X : ndarray, shape (N, 3)
            ``A^-1 b``; NaN or inf where ``A`` is singular (the caller masks them).
        conditioning : ndarray, shape (N,)
            ``3 det(A) / (tr(A) I2(A))`` with ``I2`` the sum of the principal 2x2
            minors: for a positive semi-definite ``A`` with eigenvalues
            ``l1 >= l2 >= l3`` it lies between ``l3 / (3 l1)`` and ``3 l3 / l1``, so it
            is the reciprocal condition number within a factor of 3; 0 for singular
            ``A`` (parallel rays), NaN for an empty one.
        """
        X, det, c00, c11, c22 = self._solve()
        a00, _, _, a11, _, a22 = self.a
        with np.errstate(divide="ignore", invalid="ignore"):
            conditioning = 3.0 * det / ((a00 + a11 + a22) * (c00 + c11 + c22))
        return X, conditioning

    def points(self) -> FloatArray:
        """``A^-1 b`` of every system, shape (N, 3), without the conditioning of
        :meth:`solve` (for intermediate passes)."""
        return self._solve()[0]

    def _solve(self) -> tuple[FloatArray, ...]:
        """``A^-1 b`` (N, 3), ``det(A)`` and the diagonal cofactors (N,) by the adjugate."""
        a00, a01, a02, a11, a12, a22 = self.a
        b0, b1, b2 = self.b
        c00 = a11 * a22 - a12 * a12
        c01 = a02 * a12 - a01 * a22
        c02 = a01 * a12 - a02 * a11
        c11 = a00 * a22 - a02 * a02
        c12 = a01 * a02 - a00 * a12
        c22 = a00 * a11 - a01 * a01
        det = a00 * c00 + a01 * c01 + a02 * c02
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / det
            X = np.empty((det.size, 3))
            X[:, 0] = (c00 * b0 + c01 * b1 + c02 * b2) * inv
            X[:, 1] = (c01 * b0 + c11 * b1 + c12 * b2) * inv
            X[:, 2] = (c02 * b0 + c12 * b1 + c22 * b2) * inv
        return X, det, c00, c11, c22
