"""Markers from the readings of calibrated linear CCDs (position sensors of 3 CCDs each).

Each reading is a plane (:func:`~spotlab.reconstruction.planes.linear_sensor_plane`);
a marker is the least-squares intersection of its good planes over every CCD
(:func:`~spotlab.reconstruction.planes.intersect_planes`). The calibration is one
record per CCD, as a WSX hub stores it (docs/protocols/wsx.md §4.4).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from spotlab.core.errors import ReconstructionError
from spotlab.reconstruction.planes import PlaneIntersection, intersect_planes, linear_sensor_plane
from spotlab.reconstruction.rigid import rigid_pose

F64 = NDArray[np.float64]

__all__ = [
    "LinearSensorCalibration",
    "SensorRegistration",
    "markers_from_readings",
    "register_sensors",
]


@dataclass(frozen=True)
class LinearSensorCalibration:
    """Calibration of C linear CCDs in one frame (mm).

    Attributes
    ----------
    R : ndarray, shape (C, 3, 3)
        World -> CCD rotations (orthonormal).
    t : ndarray, shape (C, 3)
        Translations (mm): ``x = R X + t``.
    focal, principal : ndarray, shape (C,)
        Principal distance and point (px).
    axis : ndarray of int, shape (C,)
        Measured axis of each CCD (0: x, 1: y).
    """

    R: F64
    t: F64
    focal: F64
    principal: F64
    axis: NDArray[np.int64]

    @classmethod
    def from_records(cls, records: Sequence[Mapping[str, Any]]) -> LinearSensorCalibration:
        """From per-CCD records (``axis``, ``focal``, ``principal``, ``R``, ``t``), in order.

        Rotations stored in single precision are made orthonormal again (the nearest
        rotation, by SVD).

        Raises
        ------
        ReconstructionError
            For no record, or a record that lacks a field or is not a rotation.
        """
        if not records:
            raise ReconstructionError("no CCD calibration records")
        try:
            R = np.array([r["R"] for r in records], dtype=np.float64).reshape(-1, 3, 3)
            t = np.array([r["t"] for r in records], dtype=np.float64).reshape(-1, 3)
            focal = np.array([r["focal"] for r in records], dtype=np.float64)
            principal = np.array([r["principal"] for r in records], dtype=np.float64)
            axis = np.array([r["axis"] for r in records], dtype=np.int64)
        except (KeyError, TypeError, ValueError) as exc:
            raise ReconstructionError(f"a CCD calibration record is incomplete: {exc}") from None
        u, _, vt = np.linalg.svd(R)
        R = u @ vt
        if np.any(np.linalg.det(R) <= 0.0):
            raise ReconstructionError("a CCD calibration holds a reflection, not a rotation")
        return cls(R, t, focal, principal, axis)

    @property
    def n_ccds(self) -> int:
        return int(self.focal.shape[0])

    def subset(self, ccds: Any) -> LinearSensorCalibration:
        """The calibration of some CCDs (an index array or slice)."""
        return LinearSensorCalibration(
            self.R[ccds], self.t[ccds], self.focal[ccds], self.principal[ccds], self.axis[ccds]
        )

    def moved(self, ccds: Any, R: F64, t: F64) -> LinearSensorCalibration:
        """The calibration with the frame of ``ccds`` changed by ``Y0 = R Y + t``."""
        Rc, tc = self.R.copy(), self.t.copy()
        Rc[ccds] = self.R[ccds] @ R.T
        tc[ccds] = self.t[ccds] - np.einsum("cij,j->ci", Rc[ccds], t)
        return LinearSensorCalibration(Rc, tc, self.focal, self.principal, self.axis)


@dataclass(frozen=True)
class SensorRegistration:
    """Position sensors registered to the first one with the markers they share.

    Attributes
    ----------
    calibration : LinearSensorCalibration
        Every CCD in the first sensor's frame.
    rms : list of float
        Per sensor, the RMS distance (mm) of its own marker positions from the first
        sensor's after registration (0 for the first).
    points : list of int
        Marker samples each registration used.
    """

    calibration: LinearSensorCalibration
    rms: list[float]
    points: list[int]


def register_sensors(
    readings: Any, calibration: LinearSensorCalibration, ccds_per_sensor: int = 3
) -> SensorRegistration:
    """Register position sensors calibrated each in its own frame, with a shared rigid object.

    Each position sensor's three CCDs fix a marker alone; the markers one sensor sees
    and the first sensor sees at the same firing instants are one rigid object in two
    frames, and the least-squares rigid motion between them (:func:`rigid_pose`)
    carries that sensor's CCDs into the first sensor's frame.

    Parameters
    ----------
    readings : array_like, shape (..., C)
        Readings (px) of every CCD, NaN where missing; C = ``ccds_per_sensor`` x S.
    calibration : LinearSensorCalibration
        Every CCD in its own sensor's frame.

    Raises
    ------
    ReconstructionError
        If a sensor shares fewer than 3 marker samples with the first, or they are
        collinear.
    """
    r = np.asarray(readings, dtype=np.float64).reshape(-1, calibration.n_ccds)
    k = ccds_per_sensor
    n_sensors = calibration.n_ccds // k
    own = [
        markers_from_readings(
            r[:, s * k : (s + 1) * k], calibration.subset(slice(s * k, (s + 1) * k))
        ).points
        for s in range(n_sensors)
    ]
    cal, rms, used = calibration, [0.0], [int(np.isfinite(own[0]).all(-1).sum())]
    for s in range(1, n_sensors):
        both = np.isfinite(own[0]).all(-1) & np.isfinite(own[s]).all(-1)
        if both.sum() < 3:
            raise ReconstructionError(
                f"position sensor {s} shares {int(both.sum())} marker samples with sensor 0: "
                "at least 3 (not collinear) are needed to register it"
            )
        pose = rigid_pose(own[s][both], own[0][both][None])
        if not pose.valid[0]:
            raise ReconstructionError(f"position sensor {s}: the shared markers are collinear")
        cal = cal.moved(slice(s * k, (s + 1) * k), pose.R[0], pose.t[0])
        rms.append(float(pose.rms[0]))
        used.append(int(both.sum()))
    return SensorRegistration(cal, rms, used)


def markers_from_readings(
    readings: Any, calibration: LinearSensorCalibration, valid: Any = None
) -> PlaneIntersection:
    """Marker positions from CCD readings.

    Parameters
    ----------
    readings : array_like, shape (..., C)
        Reading of each CCD (px); NaN for none.
    calibration : LinearSensorCalibration
        The C CCDs.
    valid : array_like of bool, shape (..., C), optional
        Readings to use (default: the finite ones).

    Returns
    -------
    PlaneIntersection
        Points (..., 3) mm; NaN where fewer than 3 planes or ill-conditioned.
    """
    r = np.asarray(readings, dtype=np.float64)
    c = calibration.n_ccds
    if r.shape[-1:] != (c,):
        raise ReconstructionError(f"readings must end in {c} CCDs, got shape {r.shape}")
    use = np.isfinite(r) if valid is None else np.asarray(valid, dtype=bool) & np.isfinite(r)
    normals = np.full((*r.shape, 3), np.nan)
    offsets = np.full(r.shape, np.nan)
    for k in range(c):
        n, d = linear_sensor_plane(
            np.where(use[..., k], r[..., k], np.nan),
            focal=float(calibration.focal[k]),
            principal=float(calibration.principal[k]),
            R=calibration.R[k],
            t=calibration.t[k],
            axis=int(calibration.axis[k]),
        )
        normals[..., k, :] = n
        offsets[..., k] = d
    if not np.isfinite(offsets).any():
        nan = np.full((*r.shape[:-1], 3), np.nan)
        shape = r.shape[:-1]
        return PlaneIntersection(
            nan, np.full(r.shape, np.nan), np.full(shape, np.nan), np.full(shape, np.inf),
            np.zeros(shape, dtype=np.int64), np.ones(shape, dtype=bool),
        )  # fmt: skip
    return intersect_planes(normals, offsets)
