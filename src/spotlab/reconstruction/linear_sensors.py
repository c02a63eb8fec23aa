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

F64 = NDArray[np.float64]

__all__ = ["LinearSensorCalibration", "markers_from_readings"]


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
