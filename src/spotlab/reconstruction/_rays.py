"""Viewing rays of image points: fast undistortion of one camera's observations.

The inverse of the Brown model is the expensive part of triangulating many points. The
geometry layer's :meth:`Camera.normalize` iterates Newton's method point by point
until each one converges; here every observation of a camera takes the same short
sequence of steps (one fixed-point division, then two Newton steps with the 2x2
Jacobian inverted in closed form); only those whose last step is not yet tiny take
more steps, and failing these go to :meth:`Camera.normalize`. Newton converges
quadratically, so a last step of at most ``_STEP_TOL`` leaves an error of the order of
its square (below 1e-12 in normalised units, i.e. about 1e-9 px).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from spotlab.core.errors import CalibrationError, ReconstructionError
from spotlab.geometry import Camera

FloatArray = NDArray[np.float64]

#: Largest last Newton step (normalised units) accepted without a fallback.
_STEP_TOL = 1e-7
_NEWTON_STEPS = 2
_EXTRA_STEPS = 6  # for the few observations the first steps leave short


def brown(x: FloatArray, y: FloatArray, dist: FloatArray) -> tuple[FloatArray, ...]:
    """Brown distortion of ideal normalised coordinates and its Jacobian.

    Parameters
    ----------
    x, y : ndarray, shape (N,)
        Ideal normalised coordinates.
    dist : ndarray, shape (5,)
        ``(k1, k2, p1, p2, k3)`` (OpenCV order).

    Returns
    -------
    xd, yd, j00, j01, j11 : ndarray, shape (N,)
        Distorted coordinates and the symmetric Jacobian ``d(xd, yd) / d(x, y)``
        (``j10 = j01``), the model of :func:`spotlab.geometry.distort_normalized`.
    """
    k1, k2, p1, p2, k3 = (float(c) for c in dist)
    xx, yy, xy = x * x, y * y, x * y
    r2 = xx + yy
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    slope = 2.0 * (k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2))  # 2 d radial / d r^2
    xd = x * radial + 2.0 * p1 * xy + p2 * (r2 + 2.0 * xx)
    yd = y * radial + p1 * (r2 + 2.0 * yy) + 2.0 * p2 * xy
    j00 = radial + xx * slope + 2.0 * p1 * y + 6.0 * p2 * x
    j01 = xy * slope + 2.0 * (p1 * x + p2 * y)
    j11 = radial + yy * slope + 6.0 * p1 * y + 2.0 * p2 * x
    return xd, yd, j00, j01, j11


def normalized_coordinates(
    camera: Camera, u: FloatArray, v: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Undistorted normalised coordinates of one camera's pixels.

    Parameters
    ----------
    camera : Camera
        The observing camera.
    u, v : ndarray, shape (N,)
        Pixel coordinates; NaN where the camera does not see the point.

    Returns
    -------
    x, y : ndarray, shape (N,)
        Ideal normalised coordinates: the ray of a pixel is ``(x, y, 1)`` in the
        camera frame. NaN stays NaN.

    Raises
    ------
    ReconstructionError
        When a pixel lies where the distortion model has no inverse.
    """
    K = camera.K
    y_d = (v - K[1, 2]) * (1.0 / K[1, 1])
    x_d = (u - K[0, 2] - K[0, 1] * y_d) * (1.0 / K[0, 0])
    k1, k2, p1, p2, k3 = (float(c) for c in camera.dist)
    if not (k1 or k2 or p1 or p2 or k3):
        return x_d, y_d
    r2 = x_d * x_d + y_d * y_d
    x = x_d / (1.0 + r2 * (k1 + r2 * (k2 + r2 * k3)))
    y = y_d / (1.0 + r2 * (k1 + r2 * (k2 + r2 * k3)))
    for _ in range(_NEWTON_STEPS - 1):
        _newton_step(x, y, x_d, y_d, camera.dist)
    step = _newton_step(x, y, x_d, y_d, camera.dist)
    slow = np.flatnonzero(~(step <= _STEP_TOL) & np.isfinite(x_d) & np.isfinite(y_d))
    for _ in range(_EXTRA_STEPS):
        if not slow.size:
            return x, y
        xs, ys = x[slow], y[slow]
        step = _newton_step(xs, ys, x_d[slow], y_d[slow], camera.dist)
        x[slow] = xs
        y[slow] = ys
        slow = slow[~(step <= _STEP_TOL)]
    if slow.size:
        # Beyond the fold of the polynomial or not converging: the geometry layer decides.
        try:
            exact = camera.normalize(np.stack([u[slow], v[slow]], axis=-1))
        except CalibrationError as exc:
            raise ReconstructionError(f"camera {camera.name!r}: {exc}") from None
        _, _, j00, j01, j11 = brown(exact[:, 0], exact[:, 1], camera.dist)
        if not np.all((j00 * j11 - j01 * j01 > 0.0) & (j00 + j11 > 0.0)):
            raise ReconstructionError(
                f"camera {camera.name!r}: pixels beyond the radius where the distortion "
                "polynomial turns back; no unique ray there"
            )
        x[slow] = exact[:, 0]
        y[slow] = exact[:, 1]
    return x, y


def _newton_step(
    x: FloatArray, y: FloatArray, x_d: FloatArray, y_d: FloatArray, dist: FloatArray
) -> FloatArray:
    """One Newton step towards ``brown(x, y) = (x_d, y_d)`` in place; returns its size
    (inf where the Jacobian is not positive definite)."""
    xd, yd, j00, j01, j11 = brown(x, y, dist)
    ex = xd - x_d
    ey = yd - y_d
    det = j00 * j11 - j01 * j01
    inv_det = 1.0 / det
    dx = (j11 * ex - j01 * ey) * inv_det
    dy = (j00 * ey - j01 * ex) * inv_det
    x -= dx
    y -= dy
    # A Jacobian that is not positive definite: the folded branch (no unique inverse).
    ok = (det > 0.0) & (j00 + j11 > 0.0)
    return np.asarray(np.where(ok, np.maximum(np.abs(dx), np.abs(dy)), np.inf))


def world_rays(camera: Camera, u: FloatArray, v: FloatArray) -> FloatArray:
    """Directions of the viewing rays in the world frame, shape (3, N), not unit length.

    The ray of pixel ``(u, v)`` is ``center + s * d`` with ``d = R' (x, y, 1)``
    (Woltring & Huiskes 1990, Eq. 6b before normalisation).
    """
    x, y = normalized_coordinates(camera, u, v)
    R = camera.R
    return np.stack([R[0, k] * x + R[1, k] * y + R[2, k] for k in range(3)])
