"""Observations for ``spotlab calibrate``: npz arrays, CSV tables, or recordings.

Three ways in, one result (:class:`WandObservations`):

- **npz**: arrays ``wand`` (F, C, 2, 2), ``frame`` (C, P, 2), ``frame_points`` (P, 3)
  and ``image_size`` (2,) or (C, 2); optional ``names`` (C,) and ``wand_length``.
- **CSV**: a wand table with a header row and one row per frame, columns
  ``cam{c}_end{e}_u`` and ``cam{c}_end{e}_v`` (c = 1..C, e = 1, 2; an empty cell or NaN
  where unseen), and a reference-object table with one row per marker, columns ``X``,
  ``Y``, ``Z`` (mm) and ``cam{c}_u``, ``cam{c}_v``.
- **recordings** (``.spj``) of a SELSPOT-style system: the wand's two markers named by
  their marker (LED) numbers in a wand-dance recording, the reference object's markers
  in a static recording (averaged over its frames), their coordinates from a CSV with
  columns ``X``, ``Y``, ``Z``. Detector counts are the image coordinates (4096 x 4096).
"""

from __future__ import annotations

import csv
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from spotlab.acquisition.replay import replay
from spotlab.console.decoding import decoder_for
from spotlab.console.errors import CommandError

__all__ = ["WandObservations", "load_csv", "load_npz", "load_recordings"]

FloatArray = NDArray[np.float64]

#: Image size of a lateral-photodiode camera in detector counts (12-bit coordinates).
PSD_IMAGE_SIZE = (4096, 4096)


@dataclass
class WandObservations:
    """Everything ``wand_calibrate`` needs."""

    wand: FloatArray
    frame: FloatArray
    frame_points: FloatArray
    image_size: FloatArray
    names: list[str] | None = None
    wand_length: float | None = None


def load_npz(path: Path) -> WandObservations:
    """Read an npz file of arrays (see the module docstring)."""
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {k: data[k] for k in data.files}
    except (OSError, ValueError) as exc:
        raise CommandError(f"{path}: not a readable npz file ({exc})") from None
    missing = {"wand", "frame", "frame_points", "image_size"} - set(arrays)
    if missing:
        raise CommandError(f"{path}: missing array(s) {', '.join(sorted(missing))}")
    names = [str(n) for n in arrays["names"]] if "names" in arrays else None
    length = float(arrays["wand_length"]) if "wand_length" in arrays else None
    return WandObservations(
        wand=np.asarray(arrays["wand"], dtype=np.float64),
        frame=np.asarray(arrays["frame"], dtype=np.float64),
        frame_points=np.asarray(arrays["frame_points"], dtype=np.float64),
        image_size=np.asarray(arrays["image_size"], dtype=np.float64),
        names=names,
        wand_length=length,
    )


def _table(path: Path) -> tuple[list[str], FloatArray]:
    try:
        with path.open(newline="") as fh:
            rows = list(csv.reader(fh))
    except OSError as exc:
        raise CommandError(f"{path}: {exc.strerror}") from None
    if len(rows) < 2:
        raise CommandError(f"{path}: needs a header row and at least one data row")
    header = [h.strip() for h in rows[0]]
    values = np.full((len(rows) - 1, len(header)), np.nan)
    for i, row in enumerate(rows[1:]):
        if len(row) != len(header):
            raise CommandError(
                f"{path}: row {i + 2} has {len(row)} cells, the header has {len(header)}"
            )
        for j, cell in enumerate(row):
            cell = cell.strip()
            if cell:
                try:
                    values[i, j] = float(cell)
                except ValueError:
                    raise CommandError(
                        f"{path}: row {i + 2}, column {header[j]!r}: {cell!r} is not a number"
                    ) from None
    return header, values


def _cameras(header: Sequence[str], pattern: str, path: Path) -> int:
    found = {int(m.group(1)) for h in header if (m := re.fullmatch(pattern, h))}
    if not found:
        raise CommandError(f"{path}: no camera columns like {pattern!r} in the header")
    if found != set(range(1, max(found) + 1)):
        raise CommandError(f"{path}: camera columns must be numbered 1..C, found {sorted(found)}")
    return max(found)


def _column(header: Sequence[str], values: FloatArray, name: str, path: Path) -> FloatArray:
    try:
        return values[:, list(header).index(name)]
    except ValueError:
        raise CommandError(f"{path}: column {name!r} is missing") from None


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
        raise CommandError(f"{frame_csv}: the reference table must have the wand's {C} cameras")
    points = np.stack([_column(fheader, fvalues, a, frame_csv) for a in "XYZ"], axis=1)
    frame = np.stack(
        [
            np.stack([_column(fheader, fvalues, f"cam{c + 1}_{a}", frame_csv) for a in "uv"], 1)
            for c in range(C)
        ]
    )
    return WandObservations(wand, frame, points, np.asarray(image_size, dtype=np.float64))


def _recorded_markers(path: Path, markers: Sequence[int]) -> FloatArray:
    """Image points (F, C, len(markers), 2) of the named markers (1-based) in a recording."""
    blocks = []
    for _name, block in replay(path, decoder_for):
        blocks.append(block.data)
    if not blocks:
        raise CommandError(f"{path}: the recording holds no frames")
    data = np.concatenate(blocks, axis=0)  # (F, M, C, V)
    M = data.shape[1]
    bad = [m for m in markers if not 1 <= m <= M]
    if bad:
        raise CommandError(f"{path}: marker(s) {bad} not in the recording (it has 1..{M})")
    idx = [m - 1 for m in markers]
    return data[:, idx, :, :2].transpose(0, 2, 1, 3)


def load_recordings(
    wand_recording: Path,
    wand_markers: Sequence[int],
    frame_recording: Path,
    frame_markers: Sequence[int],
    frame_points_csv: Path,
) -> WandObservations:
    """Wand and reference-object observations from SELSPOT-style recordings."""
    if len(wand_markers) != 2:
        raise CommandError("--wand-markers takes the two marker numbers of the wand's ends")
    wand = _recorded_markers(wand_recording, wand_markers)
    static = _recorded_markers(frame_recording, frame_markers)
    with np.errstate(invalid="ignore"):
        seen = np.isfinite(static).all(axis=-1).sum(axis=0)
    frame = np.where(
        seen[..., None] > 0,
        np.nanmean(np.where(np.isfinite(static), static, np.nan), axis=0)
        if static.size
        else static,
        np.nan,
    )
    header, values = _table(frame_points_csv)
    points = np.stack([_column(header, values, a, frame_points_csv) for a in "XYZ"], axis=1)
    if points.shape[0] != len(frame_markers):
        raise CommandError(
            f"{frame_points_csv}: {points.shape[0]} rows for {len(frame_markers)} frame markers"
        )
    return WandObservations(wand, frame, points, np.asarray(PSD_IMAGE_SIZE, dtype=np.float64))
