"""Writing C3D files: Intel float, metadata by the ``c3d`` package's Writer, frames by numpy.

See docs/files.md for what is written (units, residuals, analog scales, events) and
how trials longer than 65 535 frames are stored.
"""

from __future__ import annotations

import functools
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from spotlab.io.c3d_files import _import_c3d
from spotlab.io.trial import FileFormatError, Trial


class _FrameStub:
    """Stands in for the c3d Writer's frame list: its length, first frame and our data."""

    def __init__(
        self, n_frames: int, points: np.ndarray, analog: np.ndarray, data: np.ndarray
    ) -> None:
        self._n = n_frames
        self._first = (points, analog)
        self.data = data  # the data section, from _data_section

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

    block = _data_section(trial, per_frame, channels)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # "No point data found" and the like
            writer = _writer_class(c3d)(
                point_rate=trial.point_rate, point_scale=-1.0, point_units="mm  "
            )
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
                n_frames, np.zeros((n_markers, 5)), np.zeros((channels, per_frame)), block
            )
            with open(path, "wb") as handle:
                writer.write(handle)
    except OSError as exc:
        raise FileFormatError(path, f"cannot write the file: {exc.strerror or exc}") from exc
    except Exception as exc:
        raise FileFormatError(path, f"C3D writer failed ({type(exc).__name__}: {exc})") from exc


@functools.cache
def _writer_class(c3d: Any) -> Any:
    """The ``c3d`` package's Writer with one write of our data section for its frame loop.

    Made once per module object: a class defined at each call would keep the data
    section alive (through the reference cycle every class has) until the garbage
    collector runs.
    """

    class _Writer(c3d.Writer):
        def _write_frames(self, handle: Any) -> None:
            handle.write(memoryview(self._frames.data))
            self._pad_block(handle)

        @property
        def first_frame(self) -> int:
            # c3d 0.6 decodes ACTUAL_START_FIELD's two 16-bit words as lo + hi * 65535
            # (and writes that back): a first frame past 65535 came out one lower per
            # 65536. The words are the low and high halves of a 32-bit number.
            param = self.get("TRIAL:ACTUAL_START_FIELD")
            if param is not None:
                words = param.uint16_array
                return int(words[0]) + int(words[1]) * 65536
            return int(self.header.first_frame)

    return _Writer


def _data_section(trial: Trial, per_frame: int, channels: int) -> np.ndarray:
    """The C3D data section as one float32 array, built without a loop over frames.

    Returns
    -------
    ndarray, shape (F, 4 M + per_frame * channels), little-endian float32, C-contiguous
        Row f is frame f as the file stores it: x, y, z and the residual word of each
        marker (0, 0, 0 and -1 when any coordinate is not finite; residual 0 otherwise),
        then the frame's analog samples, sample by sample, channel by channel.
    """
    n_frames, n_markers = trial.n_frames, trial.n_markers
    block = np.empty((n_frames, 4 * n_markers + per_frame * channels), dtype="<f4")
    pts = block[:, : 4 * n_markers].reshape(n_frames, n_markers, 4)  # a view into block
    finite = np.isfinite(trial.points)
    missing = ~(finite[:, :, 0] & finite[:, :, 1] & finite[:, :, 2])
    pts[:, :, :3] = trial.points  # rounded to float32
    pts[:, :, 3] = 0.0
    pts[missing] = (0.0, 0.0, 0.0, -1.0)
    if channels:
        block[:, 4 * n_markers :] = trial.analog.reshape(n_frames, per_frame * channels)
    return block


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
