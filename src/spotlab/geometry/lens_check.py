"""Is a camera's lens model usable over its whole image? Inversion, round trip, no fold.

A distortion polynomial fitted to points in the middle of an image can turn back (fold)
before the image's edge: beyond that radius two ideal rays map to one pixel, and pixels
near the edge have no inverse at all, so a later trial whose markers reach there cannot
be reconstructed. :func:`lens_problems` checks a camera on a grid over its full image:

1. every grid pixel is undistorted (Newton iteration with convergence and fold check,
   :func:`spotlab.geometry.distortion.undistort_normalized`);
2. the round trip ``undistort(distort(x))`` returns ``x`` for ideal points ``x`` filling
   the undistorted image, so no pixel of the image has a second preimage;
3. the radial mapping ``r -> r (1 + k1 r^2 + k2 r^4 + k3 r^6)`` is increasing from the
   centre to beyond the image's farthest corner, and the Jacobian determinant of the
   full model is positive on the ideal grid.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from spotlab.core.errors import CalibrationError
from spotlab.geometry.camera import Camera
from spotlab.geometry.distortion import distort_normalized, undistort_normalized

__all__ = ["image_grid", "lens_problems"]

FloatArray = NDArray[np.float64]

#: Margin beyond the farthest image corner (fraction of its ideal radius) over which
#: the radial mapping must still be increasing.
RADIAL_MARGIN = 0.05
#: Largest round-trip error accepted, in pixels.
ROUND_TRIP_PX = 1e-6


def image_grid(size: tuple[int, int], n: int = 33) -> FloatArray:
    """Pixels on an ``n`` x ``n`` grid over the full image, edges and corners included.

    Parameters
    ----------
    size : (int, int)
        Image width and height (px).
    n : int
        Points per side.

    Returns
    -------
    ndarray, shape (n * n, 2)
        Pixel coordinates ``(u, v)`` from ``(0, 0)`` to ``(width, height)``.
    """
    w, h = size
    u, v = np.meshgrid(np.linspace(0.0, w, n), np.linspace(0.0, h, n))
    return np.stack([u.ravel(), v.ravel()], axis=1)


def _radial_turns(dist: FloatArray, r_max: float) -> float | None:
    """Smallest radius in ``[0, r_max]`` where ``d(r radial(r))/dr <= 0``, else None."""
    k1, k2, k3 = dist[0], dist[1], dist[4]
    r = np.linspace(0.0, r_max, 2001)
    r2 = r * r
    slope = 1.0 + 3.0 * k1 * r2 + 5.0 * k2 * r2 * r2 + 7.0 * k3 * r2 * r2 * r2
    bad = np.flatnonzero(~(slope > 0.0))
    return float(r[bad[0]]) if bad.size else None


def lens_problems(camera: Camera, n: int = 33) -> list[str]:
    """What keeps a camera's distortion model from being inverted over its full image.

    Parameters
    ----------
    camera : Camera
        The camera; its ``size`` is the image checked.
    n : int
        Grid points per side of the image.

    Returns
    -------
    list of str
        Empty when the model inverts everywhere in the image; otherwise one sentence per
        problem found (no convergence, a second preimage, a radial fold), naming where.
    """
    dist = np.asarray(camera.dist, dtype=np.float64)
    if not np.any(dist):
        return []
    grid = image_grid(camera.size, n)
    K = camera.K
    xy_d = np.stack(
        [
            (grid[:, 0] - K[0, 2] - K[0, 1] * (grid[:, 1] - K[1, 2]) / K[1, 1]) / K[0, 0],
            (grid[:, 1] - K[1, 2]) / K[1, 1],
        ],
        axis=1,
    )
    try:
        xy = undistort_normalized(xy_d, dist)
    except CalibrationError as exc:
        return [f"inside its image: {exc}"]
    problems: list[str] = []
    r_corner = float(np.max(np.linalg.norm(xy, axis=1)))
    turn = _radial_turns(dist, (1.0 + RADIAL_MARGIN) * r_corner)
    if turn is not None:
        problems.append(
            f"the radial distortion turns back at {100 * turn / r_corner:.0f} % of the "
            "distance to the image corner (a fold: two rays on one pixel)"
        )
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    gx, gy = np.meshgrid(np.linspace(lo[0], hi[0], n), np.linspace(lo[1], hi[1], n))
    ideal = np.stack([gx.ravel(), gy.ravel()], axis=1)
    ideal = ideal[np.linalg.norm(ideal, axis=1) <= r_corner]
    try:
        back = undistort_normalized(distort_normalized(ideal, dist), dist)
    except CalibrationError as exc:
        problems.append(f"round trip undistort(distort(x)) fails: {exc}")
        return problems
    err_px = float(np.max(np.abs(back - ideal) * [K[0, 0], K[1, 1]]))
    if not err_px <= ROUND_TRIP_PX:
        problems.append(
            f"round trip undistort(distort(x)) misses by up to {err_px:.3g} px: some pixels "
            "have two preimages"
        )
    return problems
