"""Tracks of 3-D points in time: prediction, association of blobs, update.

Each track predicts its next position at constant velocity; the prediction is projected
into every camera and the blobs are assigned to the projections camera by camera, within
a pixel gate, by the Hungarian algorithm (:func:`scipy.optimize.linear_sum_assignment`)
where several compete. The gate grows with the frames a track has been missed, so a
short occlusion is bridged; a track missed longer than the caller's limit is deleted.
Tracking in the images with a 3-D prediction costs a few array operations per frame,
where epipolar matching of all blobs (:mod:`.correspondence`) costs a search.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import linear_sum_assignment

from spotlab.reconstruction.identification.geometry import RigGeometry, camera_slots

__all__ = ["Tracks", "associate"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]


@dataclass
class Tracks:
    """The tracked points (K of them), as parallel arrays.

    Attributes
    ----------
    position : ndarray, shape (K, 3)
        Last measured position (mm).
    velocity : ndarray, shape (K, 3)
        mm per frame.
    missed : ndarray of int, shape (K,)
        Frames since the last measurement.
    label : ndarray of int, shape (K,)
        Marker index in the model, -1 unlabelled.
    ghost : ndarray of bool, shape (K,)
        A reflection (below the floor): tracked so its blobs are explained, never labelled.
    age : ndarray of int, shape (K,)
        Frames the track has held its label (or existed, unlabelled).
    residual : ndarray, shape (K,)
        RMS ray error of the last measurement (undistorted px).
    views : ndarray of int, shape (K,)
        Cameras of the last measurement.
    ident : ndarray of int, shape (K,)
        Trajectory number: given when a track starts, and anew where the identifier
        doubts the track is still on the same marker (:meth:`renew`). Points with one
        number are one marker's unbroken trajectory, whatever labels they had.
    next_ident : int
        The number the next trajectory gets.
    """

    position: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))
    velocity: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))
    missed: IntArray = field(default_factory=lambda: np.zeros(0, dtype=np.intp))
    label: IntArray = field(default_factory=lambda: np.zeros(0, dtype=np.intp))
    ghost: NDArray[np.bool_] = field(default_factory=lambda: np.zeros(0, dtype=bool))
    age: IntArray = field(default_factory=lambda: np.zeros(0, dtype=np.intp))
    residual: FloatArray = field(default_factory=lambda: np.zeros(0))
    views: IntArray = field(default_factory=lambda: np.zeros(0, dtype=np.intp))
    ident: IntArray = field(default_factory=lambda: np.zeros(0, dtype=np.intp))
    next_ident: int = 0

    def __len__(self) -> int:
        return int(self.label.size)

    def predict(self) -> FloatArray:
        """Constant-velocity predictions (K, 3) for the coming frame."""
        return self.position + self.velocity * (self.missed + 1)[:, None]

    def update(self, measured: FloatArray, residual: FloatArray, views: IntArray) -> None:
        """Take this frame's measurements (K, 3), NaN where a track was missed, with
        their RMS ray errors (K,) and camera counts (K,)."""
        hit = np.isfinite(measured[:, 0])
        self.residual = residual
        self.views = views
        step = (measured - self.position) / (self.missed + 1)[:, None]
        self.velocity = np.where(hit[:, None], step, self.velocity)
        self.position = np.where(hit[:, None], measured, self.position)
        self.missed = np.where(hit, 0, self.missed + 1)
        self.age = self.age + 1

    def add(
        self, points: FloatArray, ghost: NDArray[np.bool_], residual: FloatArray, views: IntArray
    ) -> None:
        """Start unlabelled tracks at ``points`` (N, 3), at rest."""
        n = points.shape[0]
        self.residual = np.concatenate([self.residual, residual])
        self.views = np.concatenate([self.views, views])
        self.position = np.vstack([self.position, points])
        self.velocity = np.vstack([self.velocity, np.zeros((n, 3))])
        self.missed = np.concatenate([self.missed, np.zeros(n, dtype=np.intp)])
        self.label = np.concatenate([self.label, np.full(n, -1, dtype=np.intp)])
        self.ghost = np.concatenate([self.ghost, ghost])
        self.age = np.concatenate([self.age, np.zeros(n, dtype=np.intp)])
        self.ident = np.concatenate([self.ident, self._numbers(n)])

    def renew(self, mask: NDArray[np.bool_]) -> None:
        """New trajectory numbers for the tracks where ``mask`` is True (K,)."""
        rows = np.flatnonzero(mask)
        if rows.size:
            self.ident[rows] = self._numbers(rows.size)

    def _numbers(self, n: int) -> IntArray:
        out = np.arange(self.next_ident, self.next_ident + n, dtype=np.intp)
        self.next_ident += n
        return out

    def keep(self, mask: NDArray[np.bool_]) -> None:
        """Delete the tracks where ``mask`` is False."""
        if mask.all():  # the usual frame: nothing to delete, no copies
            return
        for name in (
            "position",
            "velocity",
            "missed",
            "label",
            "ghost",
            "age",
            "residual",
            "views",
            "ident",
        ):
            setattr(self, name, getattr(self, name)[mask])


def associate(
    geom: RigGeometry,
    predicted: FloatArray,
    gate_px: FloatArray,
    xy: FloatArray,
    camera: IntArray,
    usable: NDArray[np.bool_],
    slots: tuple[IntArray, int] | None = None,
) -> tuple[IntArray, NDArray[np.bool_]]:
    """Blobs for predicted points, camera by camera.

    Parameters
    ----------
    geom : RigGeometry
    predicted : ndarray, shape (K, 3)
        Predicted points (mm).
    gate_px : ndarray, shape (K,)
        Largest distance (undistorted px) between a projection and its blob.
    xy : ndarray, shape (N, 2)
        Normalised blob coordinates.
    camera : ndarray of int, shape (N,)
    usable : ndarray of bool, shape (N,)
        Blobs that may be assigned (not merged, undistorted).
    slots : (ndarray of int, int), optional
        ``camera_slots(camera, C)`` when the caller has it.

    Returns
    -------
    index : ndarray of int, shape (C, K)
        The blob assigned to track ``k`` in camera ``c``, -1 for none.
    near : ndarray of bool, shape (N,)
        Blobs within the gate of some projection (assigned or not): explained.
    """
    C, K = len(geom), predicted.shape[0]
    index = np.full((C, K), -1, dtype=np.intp)
    near = np.zeros(camera.size, dtype=bool)
    if K == 0 or camera.size == 0:
        return index, near
    proj = geom.project(predicted)  # (C, K, 2)
    slot, width = camera_slots(camera, C) if slots is None else slots
    table_x = np.full((C, width), np.nan)  # blobs camera by camera, NaN padded
    table_y = np.full((C, width), np.nan)
    table_x[camera, slot] = xy[:, 0]
    table_y[camera, slot] = xy[:, 1]
    blob = np.full((C, width), -1, dtype=np.intp)
    blob[camera, slot] = np.arange(camera.size)
    # A rough test on the squared x distances alone (normalised, a 1e-6 margin over the
    # gate) picks the few (camera, track, blob) candidates; their exact pixel distances
    # are then computed with the same operations as a full table would take.
    dx = proj[:, :, 0, None] - table_x[:, None, :]  # (C, K, W)
    dx *= dx
    limit = gate_px[None, :] / geom.f[:, None]
    limit *= limit
    limit *= 1.0 + 1e-6
    flat = np.flatnonzero(dx < limit[:, :, None])  # NaN (padding, behind) never inside
    c_n, rest = np.divmod(flat, K * width)
    k_n, w_n = np.divmod(rest, width)
    dy = proj[c_n, k_n, 1] - table_y[c_n, w_n]
    dy *= dy
    dy += dx.ravel()[flat]
    d_n = np.sqrt(dy, out=dy)
    d_n *= geom.f[c_n]
    exact = d_n < gate_px[k_n]
    c_n, k_n, w_n, d_n = c_n[exact], k_n[exact], w_n[exact], d_n[exact]
    near[blob[c_n, w_n]] = True  # within the gate of some projection: explained
    free = np.zeros((C, width), dtype=bool)
    free[camera, slot] = usable
    take = free[c_n, w_n]
    c_n, k_n, w_n, d_n = c_n[take], k_n[take], w_n[take], d_n[take]
    per_track = np.bincount(c_n * K + k_n, minlength=C * K).reshape(C, K)
    per_blob = np.bincount(c_n * width + w_n, minlength=C * width).reshape(C, width)
    # one blob for one track and that blob for no other: taken as it is
    single_n = (per_track[c_n, k_n] == 1) & (per_blob[c_n, w_n] == 1)
    index[c_n[single_n], k_n[single_n]] = blob[c_n[single_n], w_n[single_n]]
    single = np.zeros((C, K), dtype=bool)
    single[c_n[single_n], k_n[single_n]] = True
    # the rest, where tracks compete for blobs: Hungarian per camera
    contested = (per_track > 0) & ~single
    if not contested.any():
        return index, near
    inside = np.zeros((C, K, width), dtype=bool)
    inside[c_n, k_n, w_n] = True
    d = np.empty((C, K, width))
    d[c_n, k_n, w_n] = d_n
    for c in np.flatnonzero(contested.any(axis=1)):
        rows = np.flatnonzero(contested[c])
        in_rows = inside[c, rows]
        cols = np.flatnonzero(in_rows.any(axis=0))
        sub = in_rows[:, cols]
        cost = np.where(sub, d[c, rows][:, cols], 1e6)
        r, k = linear_sum_assignment(cost)
        ok = sub[r, k]
        index[c, rows[r[ok]]] = blob[c, cols[k[ok]]]
    return index, near
