"""Gaps in a stream: lost frames, time jumps, missing samples; why an instant has no value.

Between two consecutive frames ``i`` and ``i + 1`` of a stream there is a gap when

* frames were lost: ``seq[i + 1] - seq[i] > 1``;
* the stream stalled or its clock stepped: ``T[i + 1] - T[i] > (seq[i + 1] - seq[i]) *
  max_interval`` (longer than the frames between them explain);

and, for one channel (a marker's value in one sensor), when either sample is NaN. An
interval with none of these is *usable*; a resampled value is given only inside a usable
interval, never across a gap or beyond a stream's ends. The reason is kept as bit flags.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from spotlab.core.errors import SynchronisationError

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]
U8 = npt.NDArray[np.uint8]
B = npt.NDArray[np.bool_]

__all__ = [
    "LOST_FRAMES",
    "MISSING",
    "OUTSIDE",
    "TIME_GAP",
    "check_frames",
    "frame_gaps",
    "valid_runs",
]

#: The instant lies before a stream's first sample or after its last one.
OUTSIDE = 1
#: Frames were lost between the two samples around the instant (seq jumped).
LOST_FRAMES = 2
#: The two frames around the instant are further apart than the largest allowed interval.
TIME_GAP = 4
#: A sample around the instant is missing (NaN: occluded, not seen, invalid).
MISSING = 8


def check_frames(seq: npt.ArrayLike, frame_times: npt.ArrayLike) -> tuple[I64, F64]:
    """Validate a stream's sequence numbers and frame times.

    Parameters
    ----------
    seq : array_like of int, shape (F,)
        Unwrapped sequence numbers, strictly increasing.
    frame_times : array_like, shape (F,)
        Session times of the frames, s, finite and strictly increasing.

    Returns
    -------
    seq : ndarray of int64, shape (F,)
    frame_times : ndarray of float64, shape (F,)

    Raises
    ------
    SynchronisationError
        Fewer than two frames, shapes that differ, non-integer or decreasing ``seq``,
        times not finite or not strictly increasing (the first offending frame is named).
    """
    s = np.asarray(seq)
    t = np.array(frame_times, dtype=np.float64)
    if s.ndim != 1 or t.ndim != 1 or s.shape != t.shape:
        raise SynchronisationError(
            f"seq and frame times must both have shape (F,), got {s.shape} and {t.shape}"
        )
    if t.size < 2:
        raise SynchronisationError(f"a stream needs at least 2 frames to resample, got {t.size}")
    if not np.issubdtype(s.dtype, np.integer):
        raise SynchronisationError(f"seq must be integers, got dtype {s.dtype}")
    if not np.all(np.isfinite(t)):
        bad = int(np.flatnonzero(~np.isfinite(t))[0])
        raise SynchronisationError(f"frame time of frame {bad} is not finite")
    back = np.flatnonzero(np.diff(s) <= 0)
    if back.size:
        i = int(back[0])
        raise SynchronisationError(
            f"seq does not increase at frame {i + 1}: {int(s[i])} -> {int(s[i + 1])}"
        )
    back = np.flatnonzero(np.diff(t) <= 0)
    if back.size:
        i = int(back[0])
        raise SynchronisationError(
            f"frame times do not increase at frame {i + 1}: {t[i]!r} s -> {t[i + 1]!r} s "
            "(a clock that jumps backwards must be split by its clock model first)"
        )
    return s.astype(np.int64), t


def frame_gaps(seq: I64, frame_times: F64, max_interval_s: float) -> U8:
    """Gap flags of the intervals between consecutive frames.

    Parameters
    ----------
    seq : ndarray of int64, shape (F,)
        Checked sequence numbers (see :func:`check_frames`).
    frame_times : ndarray, shape (F,)
        Checked frame times, s.
    max_interval_s : float
        Largest interval between two consecutive frames that is not a gap, s (> 0, may
        be inf); per seq step when frames were lost between them.

    Returns
    -------
    ndarray of uint8, shape (F - 1,)
        ``LOST_FRAMES`` and/or ``TIME_GAP`` per interval, 0 when usable.

    Raises
    ------
    SynchronisationError
        If ``max_interval_s`` is not positive.
    """
    if not max_interval_s > 0:
        raise SynchronisationError(f"largest frame interval must be > 0 s, got {max_interval_s}")
    steps = np.diff(seq)
    lost = steps > 1
    late = np.diff(frame_times) > steps * max_interval_s
    return (np.where(lost, LOST_FRAMES, 0) | np.where(late, TIME_GAP, 0)).astype(np.uint8)


def valid_runs(mask: npt.ArrayLike) -> I64:
    """Runs of consecutive True values of a mask, per column.

    Parameters
    ----------
    mask : array_like of bool, shape (N,) or (N, C)
        For example the usable intervals of a channel, or its finite samples.

    Returns
    -------
    ndarray of int64, shape (R, 3)
        One row per run: column, first index, one past the last index; runs ordered
        by column then start.

    Examples
    --------
    >>> valid_runs([True, True, False, True]).tolist()
    [[0, 0, 2], [0, 3, 4]]
    """
    m = np.asarray(mask, dtype=bool)
    if m.ndim == 1:
        m = m[:, None]
    if m.ndim != 2:
        raise SynchronisationError(f"mask must have shape (N,) or (N, C), got {m.shape}")
    n, c = m.shape
    # Column-major with a False guard after each column, so runs never join columns.
    flat = np.zeros((c, n + 1), dtype=bool)
    flat[:, :n] = m.T
    flat = flat.ravel()
    edges = np.diff(np.concatenate([[False], flat]).astype(np.int8))
    starts = np.flatnonzero(edges == 1)
    stops = np.flatnonzero(edges == -1)
    col = starts // (n + 1)
    return np.stack([col, starts - col * (n + 1), stops - col * (n + 1)], axis=1).astype(np.int64)
