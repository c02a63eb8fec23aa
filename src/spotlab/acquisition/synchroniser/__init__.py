"""Synchroniser: a time for every sample (slot offsets included) and resampling of every
stream at common instants by cubic spline interpolation, never across a gap."""

from spotlab.acquisition.synchroniser.gaps import (
    LOST_FRAMES,
    MISSING,
    OUTSIDE,
    TIME_GAP,
    check_frames,
    frame_gaps,
    valid_runs,
)
from spotlab.acquisition.synchroniser.resample import Resampled, resample
from spotlab.acquisition.synchroniser.sample_times import sample_offsets, sample_times
from spotlab.acquisition.synchroniser.synchroniser import (
    StreamInput,
    StreamStats,
    Synchronised,
    Synchroniser,
)

__all__ = [
    "LOST_FRAMES",
    "MISSING",
    "OUTSIDE",
    "TIME_GAP",
    "Resampled",
    "StreamInput",
    "StreamStats",
    "Synchronised",
    "Synchroniser",
    "check_frames",
    "frame_gaps",
    "resample",
    "sample_offsets",
    "sample_times",
    "valid_runs",
]
