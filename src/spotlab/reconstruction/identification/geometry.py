"""The rig as identification sees it: normalised image coordinates, epipolar geometry.

Blobs are undistorted once (:meth:`FrameTriangulator.normalize`); everything after
works on ideal normalised coordinates ``(x, y)`` where the pinhole model is exact, so
epipolar lines are straight (essential matrices, Hartley & Zisserman 2004, §9.6) and
distances are turned into undistorted pixels by each camera's principal distance.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from spotlab.geometry import Rig
from spotlab.reconstruction.frame_triangulator import FrameTriangulator

__all__ = ["RigGeometry", "camera_slots"]

FloatArray = NDArray[np.float64]
_LARGEST = float(np.finfo(np.float64).max)


def _cross_matrix(v: FloatArray) -> FloatArray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def camera_slots(camera: NDArray[np.intp], n_cameras: int) -> tuple[NDArray[np.intp], int]:
    """Places of stacked blobs in a (C, width) table, camera by camera.

    Parameters
    ----------
    camera : ndarray of int, shape (N,)
    n_cameras : int

    Returns
    -------
    slot : ndarray of int, shape (N,)
        Blob ``i`` goes to ``[camera[i], slot[i]]`` (in the order given within a camera).
    width : int
        Most blobs of one camera (at least 1).
    """
    n = camera.size
    counts = np.bincount(camera, minlength=n_cameras)
    starts = np.cumsum(counts) - counts
    if n and (camera[1:] >= camera[:-1]).all():  # the usual order: camera by camera
        slot = np.arange(n) - np.repeat(starts, counts)
    else:
        order = np.argsort(camera, kind="stable")
        slot = np.empty(n, dtype=np.intp)
        slot[order] = np.arange(n) - np.repeat(starts, counts)
    return slot, max(1, int(counts.max()) if n else 1)


class RigGeometry:
    """Per-rig constants of identification, built once.

    Parameters
    ----------
    rig : Rig
        Calibrated cameras (mm).

    Attributes
    ----------
    triangulator : FrameTriangulator
    R : ndarray, shape (C, 3, 3)
    t : ndarray, shape (C, 3)
    f : ndarray, shape (C,)
        Principal distance (px) that turns normalised distances into pixels.
    E : ndarray, shape (C, C, 3, 3)
        Essential matrices: ``[x_j, 1] E[i, j] [x_i, 1]' = 0`` for the images of one
        point in cameras ``i`` and ``j``.
    E_flat : ndarray, shape (C * C, 3, 3)
        ``E`` with the camera pair ``(i, j)`` at row ``i * C + j`` (a faster gather).
    centers : ndarray, shape (C, 3)
        Perspective centres (mm).
    """

    def __init__(self, rig: Rig) -> None:
        self.rig = rig
        self.triangulator = FrameTriangulator(rig)
        self.R = np.stack([cam.R for cam in rig])
        self.t = np.stack([cam.t for cam in rig])
        self.f = np.array([np.sqrt(cam.K[0, 0] * cam.K[1, 1]) for cam in rig])
        self.centers = np.stack([cam.center for cam in rig])
        # columns of R as (C, 1, 3) arrays (project)
        self._columns = tuple(np.ascontiguousarray(self.R[:, None, :, j]) for j in range(3))
        C = len(rig)
        self.E = np.zeros((C, C, 3, 3))
        for i in range(C):
            for j in range(C):
                if i != j:
                    R_ij = self.R[j] @ self.R[i].T
                    t_ij = self.t[j] - R_ij @ self.t[i]
                    self.E[i, j] = _cross_matrix(t_ij) @ R_ij

        self.E_flat = self.E.reshape(C * C, 3, 3)  # E[i, j] is E_flat[i * C + j]
        self._pairs: dict[int, tuple[NDArray[np.intp], NDArray[np.intp]]] = {}

    def __len__(self) -> int:
        return int(self.R.shape[0])

    def pairs(self, n: int) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
        """Every pair ``a < b`` of ``n`` items (:func:`numpy.triu_indices`), kept per ``n``
        (read-only arrays)."""
        found = self._pairs.get(n)
        if found is None:
            a, b = np.triu_indices(n, 1)
            a.flags.writeable = False
            b.flags.writeable = False
            found = self._pairs[n] = (a, b)
        return found

    def normalize(
        self,
        uv: FloatArray,
        camera: NDArray[np.intp],
        slots: tuple[NDArray[np.intp], int] | None = None,
    ) -> tuple[FloatArray, NDArray[np.bool_]]:
        """Ideal normalised coordinates of stacked blobs.

        Parameters
        ----------
        uv : ndarray, shape (N, 2)
            Distorted pixels.
        camera : ndarray of int, shape (N,)
        slots : (ndarray of int, int), optional
            ``camera_slots(camera, C)`` when the caller has it.

        Returns
        -------
        xy : ndarray, shape (N, 2)
        ok : ndarray of bool, shape (N,)
            False where the lens model has no inverse at the pixel (far outside the
            calibrated image).
        """
        C = len(self)
        slot, width = camera_slots(camera, C) if slots is None else slots
        xy = np.empty((camera.size, 2))
        xy[:, 0], xy[:, 1] = self.triangulator.normalize_slots(uv, camera, slot, width)
        return xy, np.asarray(np.isfinite(xy).all(axis=1))

    def project(self, X: FloatArray) -> FloatArray:
        """Normalised coordinates of world points in every camera.

        Parameters
        ----------
        X : ndarray, shape (N, 3)
            World points (mm), NaN allowed.

        Returns
        -------
        ndarray, shape (C, N, 2)
            NaN behind a camera or for NaN points.
        """
        # R X summed as (R0 x0 + R2 x2) + R1 x1, the order np.einsum("cij,nj->cni")
        # takes, by broadcasting over the columns of R: about a third faster.
        r0, r1, r2 = self._columns
        Xc = r0 * X[:, 0, None]
        Xc += r2 * X[:, 2, None]
        Xc += r1 * X[:, 1, None]
        Xc += self.t[:, None, :]
        z = Xc[..., 2:3]
        with np.errstate(divide="ignore", invalid="ignore"):
            out = Xc[..., :2] / z
            out[~(z[..., 0] > 0.0)] = np.nan
        return np.asarray(out)

    def triangulate(
        self, xy: FloatArray, seen: NDArray[np.bool_], *, max_ray_px: float, min_views: int = 2
    ) -> tuple[FloatArray, FloatArray, NDArray[np.bool_]]:
        """Points from matched rays, dropping the worst ray of a point while it is an outlier.

        Parameters
        ----------
        xy : ndarray, shape (C, K, 2)
            Normalised coordinates of the ray of camera ``c`` for point ``k``.
        seen : ndarray of bool, shape (C, K)
            Which rays exist.
        max_ray_px : float
            Largest accepted distance between a ray and its point (undistorted px).
        min_views : int
            Points left with fewer rays are NaN.

        Returns
        -------
        X : ndarray, shape (K, 3)
            Points (mm); NaN where fewer than ``min_views`` consistent rays remain.
        ray_px : ndarray, shape (C, K)
            Ray errors (px) of the kept rays, NaN elsewhere.
        kept : ndarray of bool, shape (C, K)
            The rays that support each point.
        """
        kept = seen.copy()
        x, y = xy[..., 0], xy[..., 1]
        while True:
            X, ray_px, n_views = self.triangulator.solve(x, y, kept)
            worst = np.where(kept, ray_px, -1.0)
            # As np.nan_to_num(nan=inf) of the ray errors, without its overhead: an
            # infinite error becomes the largest float, a NaN one (no point) infinite.
            worst[worst == np.inf] = _LARGEST
            worst[np.isnan(worst)] = np.inf
            k = np.flatnonzero(worst.max(axis=0) > max_ray_px)
            if k.size == 0:
                break
            kept[np.argmax(worst[:, k], axis=0), k] = False
        n_views = kept.sum(axis=0)
        bad = (n_views < min_views) | np.isnan(X[:, 0])
        X[bad] = np.nan
        kept[:, bad] = False
        ray_px[~kept] = np.nan
        return X, ray_px, kept
