"""Brown lens distortion in OpenCV's order (k1, k2, p1, p2, k3), forward and inverse.

Woltring & Huiskes (1990, Eq. 12) write the Brown model with radial terms
``b1, b2, b3`` and tangential terms ``p, q``:

    x' = b x + p (r^2 + 2 x^2) + 2 q x y
    y' = b y + q (r^2 + 2 y^2) + 2 p x y,      b = 1 + b1 r^2 + b2 r^4 + b3 r^6

OpenCV writes the same polynomial with ``k1 = b1, k2 = b2, k3 = b3, p1 = q, p2 = p``.
spotlab applies it as OpenCV does: from ideal normalised coordinates to distorted ones
(projection); the inverse (undistortion) is solved by Newton iteration.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from spotlab.core.errors import CalibrationError

__all__ = ["distort_normalized", "undistort_normalized"]

FloatArray = NDArray[np.float64]


def distort_normalized(xy: FloatArray, dist: FloatArray) -> FloatArray:
    """Apply the Brown model to ideal normalised image coordinates.

    Parameters
    ----------
    xy : ndarray, shape (..., 2)
        Ideal normalised coordinates ``(x/z, y/z)`` in the camera frame (dimensionless).
    dist : ndarray, shape (5,)
        ``(k1, k2, p1, p2, k3)``.

    Returns
    -------
    ndarray, shape (..., 2)
        Distorted normalised coordinates.

    Notes
    -----
    ``x_d = x (1 + k1 r^2 + k2 r^4 + k3 r^6) + 2 p1 x y + p2 (r^2 + 2 x^2)`` and
    ``y_d = y (1 + k1 r^2 + k2 r^4 + k3 r^6) + p1 (r^2 + 2 y^2) + 2 p2 x y``
    (Woltring & Huiskes 1990, Eq. 12; OpenCV ``projectPoints``).
    """
    k1, k2, p1, p2, k3 = (float(v) for v in dist)
    x = xy[..., 0]
    y = xy[..., 1]
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    return np.stack([xd, yd], axis=-1)


def _jacobian(xy: FloatArray, dist: FloatArray) -> FloatArray:
    """d(x_d, y_d)/d(x, y), shape (..., 2, 2)."""
    k1, k2, p1, p2, k3 = (float(v) for v in dist)
    x = xy[..., 0]
    y = xy[..., 1]
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    dradial = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)  # d radial / d r^2
    jac = np.empty((*x.shape, 2, 2))
    jac[..., 0, 0] = radial + 2.0 * x * x * dradial + 2.0 * p1 * y + 6.0 * p2 * x
    jac[..., 0, 1] = 2.0 * x * y * dradial + 2.0 * p1 * x + 2.0 * p2 * y
    jac[..., 1, 0] = 2.0 * x * y * dradial + 2.0 * p1 * x + 2.0 * p2 * y
    jac[..., 1, 1] = radial + 2.0 * y * y * dradial + 6.0 * p1 * y + 2.0 * p2 * x
    return jac


def undistort_normalized(
    xy_distorted: FloatArray,
    dist: FloatArray,
    *,
    tol: float = 1e-12,
    max_iter: int = 50,
) -> FloatArray:
    """Invert :func:`distort_normalized` by Newton iteration.

    Parameters
    ----------
    xy_distorted : ndarray, shape (..., 2)
        Distorted normalised coordinates; NaN entries stay NaN.
    dist : ndarray, shape (5,)
        ``(k1, k2, p1, p2, k3)``.
    tol : float
        Convergence threshold on the residual ``|distort(x) - x_d|`` (normalised units;
        1e-12 is about 1e-9 px for a 1000 px principal distance).
    max_iter : int
        Newton steps allowed.

    Returns
    -------
    ndarray, shape (..., 2)
        Ideal normalised coordinates ``x`` with ``distort(x) = x_d``.

    Raises
    ------
    CalibrationError
        When a point does not converge, or converges onto the folded branch of the
        model (Jacobian determinant <= 0: beyond the radius where the polynomial turns
        back), where no unique inverse exists.

    Notes
    -----
    Newton's step ``x <- x - J(x)^-1 (distort(x) - x_d)`` starting from ``x = x_d``,
    with the analytic 2x2 Jacobian; quadratic convergence inside the invertible region
    (OpenCV's ``undistortPoints`` uses a fixed number of fixed-point steps instead, with
    no convergence check).
    """
    target = np.asarray(xy_distorted, dtype=np.float64)
    dist = np.asarray(dist, dtype=np.float64)
    if not np.any(dist):
        return target.copy()
    xy = target.copy()
    finite = np.all(np.isfinite(target), axis=-1)
    for _ in range(max_iter):
        resid = distort_normalized(xy, dist) - target
        err = np.max(np.abs(resid), axis=-1)
        pending = finite & ~(err <= tol)
        if not np.any(pending):
            break
        jac = _jacobian(xy[pending], dist)
        try:
            step = np.linalg.solve(jac, resid[pending][..., None])[..., 0]
        except np.linalg.LinAlgError:
            raise CalibrationError(
                "undistortion: the distortion model is singular at some points "
                "(zero Jacobian); no inverse there"
            ) from None
        xy[pending] -= step
    else:
        resid = distort_normalized(xy, dist) - target
        pending = finite & ~(np.max(np.abs(resid), axis=-1) <= tol)
    if np.any(pending):
        raise CalibrationError(
            f"undistortion did not converge for {int(np.count_nonzero(pending))} of "
            f"{int(np.count_nonzero(finite))} points in {max_iter} Newton steps: the points "
            "lie outside the region where the distortion model can be inverted"
        )
    folded = ~(np.linalg.det(_jacobian(xy[finite], dist)) > 0.0)
    if np.any(folded):
        raise CalibrationError(
            f"undistortion: {int(np.count_nonzero(folded))} points lie beyond the radius "
            "where the radial distortion polynomial turns back; no unique inverse there"
        )
    return xy
