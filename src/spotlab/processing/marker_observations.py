"""Observations for ``spotlab reconstruct`` and ``spotlab export``: image points of markers
per frame and camera, from npz arrays, a CSV table or a SELSPOT-style recording.

- **npz**: array ``uv`` (F, C, M, 2), pixel coordinates of marker ``m`` in camera ``c``
  at frame ``f``, NaN where unseen; optional ``rate`` (frames per second, a scalar),
  ``labels`` (M,) marker names and ``camera_names`` (C,).
- **CSV**: a header row and one row per frame, columns ``cam{c}_m{m}_u`` and
  ``cam{c}_m{m}_v`` (pixels; c = 1..C, m = 1..M, every pair present; an empty cell or
  NaN where unseen). Other columns (a frame number, a time) are ignored. The frame rate
  is not in the table: give ``--rate``.
- **recording** (``.spj``) of one SELSPOT-style (``selspot``) device: every marker of
  its LED table, in detector counts, with the rules of
  :mod:`spotlab.processing.recorded_observations` (readings dropped, 4096 x 4096 counts);
  frames lost on the link stay as gaps (NaN) in their place; the rate is the
  recording's.

Markers are called ``M1`` ... ``MM`` unless named.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from spotlab.processing.decoding import input_suffix
from spotlab.processing.errors import InputError
from spotlab.processing.npz import number, numeric_array, read_npz
from spotlab.processing.recorded_observations import frame_numbers, read_selspot, usable_counts
from spotlab.processing.tables import column, numbered, read_table

__all__ = ["OBSERVATION_SUFFIXES", "MarkerObservations", "load_observations"]

FloatArray = NDArray[np.float64]

#: Suffixes of the observation files :func:`load_observations` reads.
OBSERVATION_SUFFIXES = (".npz", ".csv", ".spj")


@dataclass
class MarkerObservations:
    """Image points of markers per frame and camera.

    Attributes
    ----------
    uv : ndarray, shape (F, C, M, 2)
        Image coordinates (px, or detector counts for a recording); NaN where unseen.
    rate_hz : float or None
        Frame rate, when the input states it.
    labels : list of str or None
        Marker names (M), when the input has them.
    camera_names : list of str or None
        Camera names (C), when the input has them.
    facts : dict
        What else is worth reporting (frames lost in a recording, ...).
    ticks : ndarray of int64, shape (F,), or None
        Device time stamp of each frame of a recording (-1 for a lost frame).
    """

    uv: FloatArray
    rate_hz: float | None = None
    labels: list[str] | None = None
    camera_names: list[str] | None = None
    facts: dict[str, Any] = field(default_factory=dict)
    ticks: NDArray[np.int64] | None = None


def load_observations(path: Path) -> MarkerObservations:
    """Read observations by the file's suffix (see the module docstring).

    Raises
    ------
    InputError
        For a missing file, an unknown suffix or a file that does not hold what its
        format needs (naming the cause).
    """
    if not path.is_file():
        raise InputError(f"{path}: no such file")
    suffix = input_suffix(path)
    if suffix == ".npz":
        return _load_npz(path)
    if suffix == ".csv":
        return _load_csv(path)
    if suffix == ".spj":
        return _load_recording(path)
    raise InputError(
        f"{path}: unknown observation format {suffix!r} ({', '.join(OBSERVATION_SUFFIXES)})"
    )


def _load_npz(path: Path) -> MarkerObservations:
    arrays = read_npz(path)
    if "uv" not in arrays:
        raise InputError(f"{path}: missing array 'uv' (F, C, M, 2)")
    uv = numeric_array(path, "uv", arrays["uv"])
    if uv.ndim != 4 or uv.shape[-1] != 2 or 0 in uv.shape:
        raise InputError(f"{path}: 'uv' must have shape (F, C, M, 2), not {uv.shape}")
    rate = number(path, "rate", arrays["rate"]) if "rate" in arrays else None
    if rate is not None and not (np.isfinite(rate) and rate > 0):
        raise InputError(f"{path}: 'rate' must be a positive number of frames per second")
    labels = [str(x) for x in arrays["labels"].ravel()] if "labels" in arrays else None
    names = [str(x) for x in arrays["camera_names"].ravel()] if "camera_names" in arrays else None
    return MarkerObservations(uv, rate, labels, names)


def _load_csv(path: Path) -> MarkerObservations:
    header, values = read_table(path)
    C = len(numbered(header, r"cam(\d+)_m\d+_[uv]", "camera", path))
    M = len(numbered(header, r"cam\d+_m(\d+)_[uv]", "marker", path))
    uv = np.empty((values.shape[0], C, M, 2))
    for c in range(C):
        for m in range(M):
            for k, axis in enumerate("uv"):
                uv[:, c, m, k] = column(header, values, f"cam{c + 1}_m{m + 1}_{axis}", path)
    return MarkerObservations(uv)


def _load_recording(path: Path) -> MarkerObservations:
    recording = read_selspot(path)
    number = frame_numbers(recording, path)
    counts = usable_counts(recording.data, recording.flags)  # (F, M, C, 2)
    uv = np.full((int(number[-1]) + 1, *counts.shape[1:]), np.nan)
    uv[number] = counts
    ticks = np.full(uv.shape[0], -1, dtype=np.int64)
    ticks[number] = recording.ticks
    facts = {
        "decoded_frames": int(number.size),
        "lost_frames": int(uv.shape[0] - number.size),
        "units": "detector counts",
    }
    return MarkerObservations(uv.transpose(0, 2, 1, 3), recording.rate_hz, facts=facts, ticks=ticks)
