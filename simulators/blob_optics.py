"""The cameras of a rig as stacked arrays, and the projection of points through all of them.

A simulator renders every frame through the same cameras: :class:`Optics` stacks
their poses, intrinsics, lenses and image sizes once, so a frame's projection
(:func:`project_many`) does not rebuild them.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from spotlab.geometry import Camera

F64 = npt.NDArray[np.float64]
B = npt.NDArray[np.bool_]


@dataclass(frozen=True)
class Optics:
    """``n`` cameras stacked (arrays are read-only).

    Attributes
    ----------
    R : ndarray, shape (n, 3, 3)
        Rotations (world to camera).
    t : ndarray, shape (n, 3)
        Translations (mm).
    fx, skew, cx, fy, cy : ndarray, shape (n, 1)
        Intrinsics (px): ``K[0, 0]``, ``K[0, 1]``, ``K[0, 2]``, ``K[1, 1]``, ``K[1, 2]``.
    k1, k2, p1, p2, k3 : ndarray, shape (n, 1)
        Brown distortion coefficients.
    size : ndarray, shape (n, 2)
        Image width and height (px).
    centers : ndarray, shape (n, 3)
        Camera centres (mm).
    """

    R: F64
    t: F64
    fx: F64
    skew: F64
    cx: F64
    fy: F64
    cy: F64
    k1: F64
    k2: F64
    p1: F64
    p2: F64
    k3: F64
    size: F64
    centers: F64

    @classmethod
    def of(cls, cams: Sequence[Camera]) -> Optics:
        """The stacked arrays of ``cams``."""
        K = np.stack([c.K for c in cams])  # (n, 3, 3)
        k1, k2, p1, p2, k3 = np.stack([c.dist for c in cams]).T[:, :, None]  # (n, 1) each
        arrays = {
            "R": np.stack([c.R for c in cams]), "t": np.stack([c.t for c in cams]),
            "fx": K[:, 0, 0, None], "skew": K[:, 0, 1, None], "cx": K[:, 0, 2, None],
            "fy": K[:, 1, 1, None], "cy": K[:, 1, 2, None],
            "k1": k1, "k2": k2, "p1": p1, "p2": p2, "k3": k3,
            "size": np.array([c.size for c in cams], dtype=np.float64),
            "centers": np.stack([c.center for c in cams]),
        }  # fmt: skip
        for a in arrays.values():
            a.flags.writeable = False
        return cls(**arrays)

    def select(self, index: Sequence[int]) -> Optics:
        """The cameras ``index`` of these (in that order)."""
        i = np.asarray(index, dtype=np.int64)
        arrays = {k: np.asarray(v)[i] for k, v in self.__dict__.items()}
        for a in arrays.values():
            a.flags.writeable = False
        return Optics(**arrays)


def project_many(
    optics: Optics, P: F64, diameter_mm: float, peak_at_4m: float
) -> tuple[F64, F64, F64, B]:
    """Image centroids (n, N, 2), diameters (px), raw peaks and in-view flags (n, N).

    Parameters
    ----------
    optics : Optics
        The ``n`` cameras.
    P : ndarray, shape (n, N, 3)
        The points each camera sees (mm; NaN: none).
    diameter_mm : float
        Marker diameter (mm): a disc of ``fx * diameter_mm / z`` px.
    peak_at_4m : float
        Peak grey level 4 m away (``peak_at_4m * (4 m / z)^2``).

    Notes
    -----
    One projection for all cameras, each with its own lens (the Brown model of
    :func:`spotlab.geometry.distortion.distort_normalized`, per camera); points
    closer than 100 mm in front of a camera, behind it or outside its image are
    not in view.
    """
    o = optics
    k1, k2, k3, p1, p2 = o.k1, o.k2, o.k3, o.p1, o.p2
    R, X = o.R[..., None], (P[..., 0], P[..., 1], P[..., 2])
    with np.errstate(invalid="ignore", divide="ignore"):
        # R X + t per coordinate, summed in the order numpy's einsum sums three terms.
        xc = [(R[:, i, 0] * X[0] + R[:, i, 2] * X[2]) + R[:, i, 1] * X[1] + o.t[:, i, None]
              for i in range(3)]  # fmt: skip
        z = xc[2]
        good = np.isfinite(z) & (z > 100.0)
        zz = np.where(good, z, 1.0)
        x, y = xc[0] / zz, xc[1] / zz
        r2 = x * x + y * y
        radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
        yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    u = o.fx * xd + o.skew * yd + o.cx
    v = o.fy * yd + o.cy
    uv = np.where(good[..., None], np.stack([u, v], axis=-1), np.nan)
    diameter = np.where(good, o.fx * diameter_mm / zz, 0.0)
    peak = np.where(good, peak_at_4m * (4000.0 / zz) ** 2, 0.0)
    with np.errstate(invalid="ignore"):
        width, height = o.size[:, 0, None] - 1, o.size[:, 1, None] - 1
        inside = good & (u >= 0) & (v >= 0) & (u <= width) & (v <= height)
    return uv, diameter, peak, np.asarray(inside)
