"""Every marker coordinate of a trial smoothed by its own GCV spline, in one batched fit."""

from __future__ import annotations

import copy
from typing import Protocol, TypeVar

import numpy as np
from numpy.typing import NDArray

from spotlab.kinematics.errors import KinematicsError
from spotlab.kinematics.spline import SmoothingSpline

FloatArray = NDArray[np.float64]


class MarkerTrial(Protocol):
    """What :func:`smooth_trial` needs of a trial (:class:`spotlab.io.Trial` has it)."""

    points: FloatArray
    point_rate: float


TrialT = TypeVar("TrialT", bound=MarkerTrial)


def smooth_trial(trial: TrialT, degree: int = 5, *, fill_gaps: bool = False) -> TrialT:
    """A copy of ``trial`` with every marker coordinate smoothed (GCVSPL-style GCV spline).

    Parameters
    ----------
    trial : Trial
        ``points`` (F, M, 3), mm, NaN where a marker was not seen, sampled at
        ``point_rate`` frames per second.
    degree : {5, 3}
        Spline degree (quintic by default).
    fill_gaps : bool
        Also give the spline's values in the gaps (NaN samples) of each marker;
        by default they stay NaN.

    Returns
    -------
    Trial
        A shallow copy of ``trial`` with new ``points`` (F, M, 3), mm. A coordinate
        with fewer than ``degree + 1`` samples present cannot be fitted and is
        left as it was.

    Raises
    ------
    KinematicsError
        ``points`` not shaped (F, M, 3) or ``point_rate`` not positive.

    Notes
    -----
    The F x 3M coordinates share their sample times and are fitted in one
    :class:`SmoothingSpline` call, each with its own GCV smoothing parameter;
    coordinates missing the same frames (the three of one marker, and all the
    markers seen throughout) share their banded work.
    """
    points = np.asarray(trial.points, dtype=np.float64)
    if points.ndim != 3 or points.shape[2] != 3:
        raise KinematicsError(f"trial points must have shape (F, M, 3), got {points.shape}")
    if not (np.isfinite(trial.point_rate) and trial.point_rate > 0):
        raise KinematicsError(f"trial point rate must be positive, got {trial.point_rate}")
    frames = points.shape[0]
    channels = points.reshape(frames, -1)
    present = np.isfinite(channels)
    fit = np.flatnonzero(present.sum(axis=0) >= degree + 1)
    smoothed = channels.copy()
    if fit.size and frames >= degree + 1:
        t = np.arange(frames) / float(trial.point_rate)
        values = SmoothingSpline(t, channels[:, fit], degree=degree)(t)
        keep = fill_gaps | present[:, fit]
        smoothed[:, fit] = np.where(keep, values, np.nan)
    out = copy.copy(trial)
    out.points = smoothed.reshape(points.shape)
    return out
