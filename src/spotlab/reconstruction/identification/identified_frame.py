"""What :class:`~.identifier.Identifier` gives for one frame: labelled markers, the
trajectories they lie on, and flags of the cameras left out."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

__all__ = ["FLOODED", "NO_BLOBS", "UNUSABLE", "IdentifiedFrame"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]

#: Camera flags of an :class:`IdentifiedFrame`.
FLOODED = 1  # more blobs than max_blobs: left out of the frame
UNUSABLE = 2  # flagged by the caller (offline, overflow)
NO_BLOBS = 4  # no blob at all


@dataclass(frozen=True)
class IdentifiedFrame:
    """Labelled markers of one frame.

    Attributes
    ----------
    points : ndarray, shape (M, 3)
        Marker positions (mm) in the model's label order; NaN where a marker was not
        reconstructed (a flagged gap, never a guess).
    residual_px : ndarray, shape (M,)
        RMS ray error of each marker (undistorted px), NaN where missing.
    n_cameras : ndarray of int, shape (M,)
        Cameras whose rays made each marker.
    unlabelled : int
        Points reconstructed but given no label (not reported).
    ghosts : int
        Points rejected as reflections (below the floor).
    camera_flags : ndarray of int, shape (C,)
        ``FLOODED``, ``UNUSABLE``, ``NO_BLOBS`` bits per camera.
    trajectory : ndarray of int, shape (M,)
        Trajectory number (:attr:`.tracking.Tracks.ident`) of each labelled marker's
        point, -1 where missing.
    loose_points : ndarray, shape (U, 3)
        The unlabelled points of the frame (mm), reflections left out.
    loose_trajectory : ndarray of int, shape (U,)
        Their trajectory numbers.
    loose_residual_px : ndarray, shape (U,)
        Their RMS ray errors (undistorted px).
    """

    points: FloatArray
    residual_px: FloatArray
    n_cameras: IntArray
    unlabelled: int
    ghosts: int
    camera_flags: IntArray
    trajectory: IntArray = field(default_factory=lambda: np.zeros(0, dtype=np.intp))
    loose_points: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))
    loose_trajectory: IntArray = field(default_factory=lambda: np.zeros(0, dtype=np.intp))
    loose_residual_px: FloatArray = field(default_factory=lambda: np.zeros(0))
