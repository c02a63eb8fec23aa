"""Writing C3D files: Intel float, metadata by the ``c3d`` package's Writer, frames by numpy.

See docs/files.md for what is written (units, residuals, analog scales, events) and
how trials longer than 65 535 frames are stored.
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

import numpy as np

from spotlab.io.c3d_files import _import_c3d
from spotlab.io.trial import FileFormatError, Trial


class _FrameStub:
    """Stands in for the c3d Writer's frame list: its length and first frame only."""

    def __init__(self, n_frames: int, points: np.ndarray, analog: np.ndarray) -> None:
        self._n = n_frames
        self._first = (points, analog)

    def __len__(self) -> int:
        return self._n

    def __getitem__(self, index: int) -> tuple[np.ndarray, np.ndarray]:
        if index != 0:
            raise IndexError(index)
        return self._first


def write_c3d(path: str | Path, trial: Trial) -> None:
    """Write ``trial`` as an Intel float C3D file (points in mm, POINT:SCALE -1).

    Coordinates and analog samples are stored as float32; analog channels with
    scale 1 and offset 0 (written out, so ezc3d can read the file). Missing
    points (NaN) get residual -1, seen points residual 0. More than 65 535 frames:
    POINT:FRAMES 65535 with the true range in TRIAL:ACTUAL_START_FIELD /
    ACTUAL_END_FIELD (and POINT:LONG_FRAMES), header last frame capped.
    """
    c3d = _import_c3d(path)
    trial.check(path)
    if trial.units != "mm":
        raise FileFormatError(path, f"points must be in mm to be written, not {trial.units!r}")
    n_frames, n_markers = trial.n_frames, trial.n_markers
    if n_frames == 0:
        raise FileFormatError(path, "a C3D file needs at least one frame")
    per_frame = trial.analog_per_frame
    channels = trial.analog.shape[1]

    pts = np.empty((n_frames, n_markers, 4), dtype="<f4")
    missing = np.asarray(~np.isfinite(trial.points).all(axis=2), dtype=bool)
    pts[:, :, :3] = np.where(missing[:, :, None], 0.0, trial.points)
    pts[:, :, 3] = np.where(missing, -1.0, 0.0)
    analog = trial.analog.astype("<f4").reshape(n_frames, per_frame * channels)
    block = np.concatenate([pts.reshape(n_frames, 4 * n_markers), analog], axis=1)
    raw = np.ascontiguousarray(block, dtype="<f4").tobytes()

    class _Writer(c3d.Writer):  # type: ignore[name-defined]
        def _write_frames(self, handle: Any) -> None:
            handle.write(raw)
            self._pad_block(handle)

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # "No point data found" and the like
            writer = _Writer(point_rate=trial.point_rate, point_scale=-1.0, point_units="mm  ")
            if channels:
                writer.analog_rate = trial.analog_rate
                writer.set_analog_labels(list(trial.analog_labels))
            writer.set_analog_scales(np.ones(channels))
            writer.set_analog_offsets(np.zeros(channels, dtype=np.int16))
            if n_markers:
                writer.set_point_labels(list(trial.labels))
            writer.set_start_frame(max(int(trial.first_frame), 1))
            if trial.events:
                _add_events(writer, trial.events)
            writer._frames = _FrameStub(
                n_frames, np.zeros((n_markers, 5)), np.zeros((channels, per_frame))
            )
            with open(path, "wb") as handle:
                writer.write(handle)
    except OSError as exc:
        raise FileFormatError(path, f"cannot write the file: {exc.strerror or exc}") from exc
    except Exception as exc:
        raise FileFormatError(path, f"C3D writer failed ({type(exc).__name__}: {exc})") from exc


def _add_events(writer: Any, events: list[tuple[str, str, float]]) -> None:
    group = writer.get_create("EVENT")
    n = len(events)
    times = np.array([[t // 60.0, t - 60.0 * (t // 60.0)] for _, _, t in events], dtype="<f4")
    group.add("USED", "Number of events", 2, "<H", n)
    for name, column in (("LABELS", 0), ("CONTEXTS", 1)):
        texts = [str(e[column]) or " " for e in events]
        width = max(len(s) for s in texts)
        group.add_str(
            name, f"Event {name.lower()}", "".join(s.ljust(width) for s in texts), width, n
        )
    group.add("TIMES", "Event times (minutes, seconds)", 4, "<f", times.tobytes(), 2, n)
