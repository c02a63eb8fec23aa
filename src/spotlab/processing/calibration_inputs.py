"""Observations for ``spotlab calibrate``: npz arrays, CSV tables, or recordings.

Three ways in, one result (:class:`WandObservations`):

- **npz**: arrays ``wand`` (F, C, 2, 2), ``frame`` (C, P, 2), ``frame_points`` (P, 3)
  and ``image_size`` (2,) or (C, 2); optional ``names`` (C,) and ``wand_length``.
- **CSV**: a wand table with a header row and one row per frame, columns
  ``cam{c}_end{e}_u`` and ``cam{c}_end{e}_v`` (c = 1..C, e = 1, 2; an empty cell or NaN
  where unseen), and a reference-object table with one row per marker, columns ``X``,
  ``Y``, ``Z`` (mm) and ``cam{c}_u``, ``cam{c}_v``.
- **recordings** (``.spj``) of one SELSPOT-style (``selspot``) system: the wand's two
  markers named by their marker numbers in a wand-dance recording, the reference
  object's markers in a static recording (averaged over its frames), their coordinates
  from a CSV with columns ``X``, ``Y``, ``Z`` (mm), one row per frame marker in the
  order of ``--frame-markers``.

Recordings, in detail:

- Markers, detector counts, the image size of 4096 x 4096 counts and the readings
  dropped (not valid, saturated, clipped at the edge) are as in
  :mod:`spotlab.processing.recorded_observations`.
- The reference object must not move: a marker whose readings in a camera spread more
  than :data:`STATIC_SD_MAX` counts (SD) is refused.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from spotlab.processing.errors import InputError
from spotlab.processing.npz import number, numeric_array, read_npz
from spotlab.processing.recorded_observations import PSD_IMAGE_SIZE, read_selspot, usable_counts
from spotlab.processing.tables import camera_count as _cameras
from spotlab.processing.tables import column as _column
from spotlab.processing.tables import read_table as _table

__all__ = ["WandObservations", "load_csv", "load_npz", "load_recordings"]

FloatArray = NDArray[np.float64]

#: Largest SD (counts) of a reference marker's readings in a static recording; the PSD
#: noise is about 2 counts at intensity 80 and grows as 1 / intensity.
STATIC_SD_MAX = 25.0


@dataclass
class WandObservations:
    """Everything ``wand_calibrate`` needs."""

    wand: FloatArray
    frame: FloatArray
    frame_points: FloatArray
    image_size: FloatArray
    names: list[str] | None = None
    wand_length: float | None = None
    units: str = "px"


def load_npz(path: Path) -> WandObservations:
    """Read an npz file of arrays (see the module docstring)."""
    arrays = read_npz(path)
    missing = {"wand", "frame", "frame_points", "image_size"} - set(arrays)
    if missing:
        raise InputError(f"{path}: missing array(s) {', '.join(sorted(missing))}")
    names = [str(n) for n in arrays["names"]] if "names" in arrays else None
    length = number(path, "wand_length", arrays["wand_length"]) if "wand_length" in arrays else None
    return WandObservations(
        wand=numeric_array(path, "wand", arrays["wand"]),
        frame=numeric_array(path, "frame", arrays["frame"]),
        frame_points=numeric_array(path, "frame_points", arrays["frame_points"]),
        image_size=numeric_array(path, "image_size", arrays["image_size"]),
        names=names,
        wand_length=length,
    )


def load_csv(wand_csv: Path, frame_csv: Path, image_size: Sequence[int]) -> WandObservations:
    """Read the wand and reference-object tables (see the module docstring)."""
    header, values = _table(wand_csv)
    C = _cameras(header, r"cam(\d+)_end[12]_u", wand_csv)
    wand = np.empty((values.shape[0], C, 2, 2))
    for c in range(C):
        for e in range(2):
            for k, axis in enumerate("uv"):
                name = f"cam{c + 1}_end{e + 1}_{axis}"
                wand[:, c, e, k] = _column(header, values, name, wand_csv)
    fheader, fvalues = _table(frame_csv)
    if _cameras(fheader, r"cam(\d+)_u", frame_csv) != C:
        raise InputError(f"{frame_csv}: the reference table must have the wand's {C} cameras")
    points = np.stack([_column(fheader, fvalues, a, frame_csv) for a in "XYZ"], axis=1)
    frame = np.stack(
        [
            np.stack([_column(fheader, fvalues, f"cam{c + 1}_{a}", frame_csv) for a in "uv"], 1)
            for c in range(C)
        ]
    )
    return WandObservations(wand, frame, points, np.asarray(image_size, dtype=np.float64))


def _selspot_readings(path: Path) -> tuple[FloatArray, NDArray[np.uint8]]:
    """Every frame of a one-stream selspot recording: data (F, M, C, 3) and flags (F, M, C)."""
    recording = read_selspot(path)
    return recording.data, recording.flags


def _recorded_markers(path: Path, markers: Sequence[int], option: str) -> FloatArray:
    """Detector counts (F, C, len(markers), 2) of the named markers (1-based), NaN if unusable."""
    if len(set(markers)) != len(markers):
        raise InputError(f"{option}: a marker is named twice ({list(markers)})")
    data, flags = _selspot_readings(path)
    M = data.shape[1]
    bad = [m for m in markers if not 1 <= m <= M]
    if bad:
        raise InputError(f"{option}: marker(s) {bad} not in {path} (it has markers 1..{M})")
    idx = [m - 1 for m in markers]
    return usable_counts(data[:, idx], flags[:, idx]).transpose(0, 2, 1, 3)


def _static_mean(static: FloatArray, markers: Sequence[int], path: Path) -> FloatArray:
    """Mean over the frames (F, C, P, 2) -> (C, P, 2), NaN where never seen; refuse motion."""
    seen = np.asarray(np.isfinite(static).all(axis=-1))  # (F, C, P)
    n = seen.sum(axis=0)[..., None]  # (C, P, 1) frames seeing each marker
    filled = np.where(seen[..., None], static, 0.0)
    mean = np.where(n > 0, filled.sum(axis=0) / np.maximum(n, 1), np.nan)
    spread = np.where(seen[..., None], static - mean, 0.0)
    sd = np.sqrt((spread**2).sum(axis=0) / np.maximum(n - 1, 1)).max(axis=-1)  # (C, P)
    if (sd > STATIC_SD_MAX).any():
        c, p = (int(i) for i in np.unravel_index(int(np.argmax(sd)), sd.shape))
        raise InputError(
            f"{path}: marker {markers[p]} moves in camera {c + 1} (SD {sd[c, p]:.0f} counts > "
            f"{STATIC_SD_MAX:g}); the reference object must stand still"
        )
    return np.asarray(mean)


def load_recordings(
    wand_recording: Path,
    wand_markers: Sequence[int],
    frame_recording: Path,
    frame_markers: Sequence[int],
    frame_points_csv: Path,
) -> WandObservations:
    """Wand and reference-object observations from SELSPOT-style recordings.

    Parameters
    ----------
    wand_recording : Path
        Journal (``.spj``) of the wand dance.
    wand_markers : sequence of int
        Marker numbers (1-based) of the wand's two ends.
    frame_recording : Path
        Journal of the static reference object (may be the wand recording itself).
    frame_markers : sequence of int
        Marker numbers of the reference object's markers.
    frame_points_csv : Path
        Their coordinates (mm): columns ``X``, ``Y``, ``Z``, one row per frame marker.

    Returns
    -------
    WandObservations
        ``wand`` (F, C, 2, 2) and ``frame`` (C, P, 2) in detector counts, the image size
        4096 x 4096 counts (see the module docstring).

    Raises
    ------
    InputError
        Naming the cause: not two wand markers, a marker named twice or not in the
        recording, a recording without frames, of another family or of several devices,
        a moving reference object, a points table whose rows do not match the markers.
    """
    if len(wand_markers) != 2:
        raise InputError("--wand-markers takes the two marker numbers of the wand's ends")
    header, values = _table(frame_points_csv)
    points = np.stack([_column(header, values, a, frame_points_csv) for a in "XYZ"], axis=1)
    if points.shape[0] != len(frame_markers):
        raise InputError(
            f"{frame_points_csv}: {points.shape[0]} rows for {len(frame_markers)} frame markers"
        )
    empty = np.flatnonzero(~np.isfinite(points).all(axis=1))
    if empty.size:
        raise InputError(f"{frame_points_csv}: row {empty[0] + 2} lacks a coordinate")
    wand = _recorded_markers(wand_recording, wand_markers, "--wand-markers")
    static = _recorded_markers(frame_recording, frame_markers, "--frame-markers")
    if static.shape[1] != wand.shape[1]:
        raise InputError(
            f"{frame_recording}: {static.shape[1]} cameras, the wand recording has {wand.shape[1]}"
        )
    frame = _static_mean(static, frame_markers, frame_recording)
    return WandObservations(
        wand, frame, points, np.asarray(PSD_IMAGE_SIZE, dtype=np.float64), units="counts"
    )
