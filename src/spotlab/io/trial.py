"""A motion-capture trial in memory: 3-D marker trajectories, analog channels, events.

This is what the exchange-file readers return and the writers take
(:mod:`spotlab.io.c3d_files`, :mod:`spotlab.io.trc_files`). Lengths are always
millimetres; a missing marker sample is NaN in all three coordinates.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from spotlab.core.errors import RecordingError

FloatArray = npt.NDArray[np.float64]

#: Length units a file may declare and their factor to millimetres.
MM_PER_UNIT = {"mm": 1.0, "cm": 10.0, "m": 1000.0}


class FileFormatError(RecordingError):
    """An exchange file (C3D, TRC) cannot be read or written; the message names the file."""

    def __init__(self, path: str | Path, cause: str) -> None:
        super().__init__(f"{path}: {cause}")
        self.path = str(path)
        self.cause = cause


@dataclass
class Trial:
    """Marker trajectories and analog data of one trial.

    Attributes
    ----------
    points : ndarray, shape (F, M, 3), float64
        Marker positions in millimetres; NaN where a marker was not seen.
    labels : list of str, length M
        Marker names.
    point_rate : float
        Frames per second.
    analog : ndarray, shape (S, A), float64
        Analog samples in physical units (scale and offset applied); S is
        F times the number of analog samples per frame.
    analog_labels : list of str, length A
    analog_rate : float
        Analog samples per second per channel (0 when there are no channels).
    first_frame : int
        Number of the first frame (C3D counts from 1).
    events : list of (label, context, time_s)
        Time in seconds as stored in the file.
    units : str
        Unit of ``points`` ("mm" unless the file declared a unit we cannot convert).
    metadata : dict
        Anything else worth keeping (file format details, header events, notes).
    """

    points: FloatArray
    labels: list[str]
    point_rate: float
    analog: FloatArray = field(default_factory=lambda: np.zeros((0, 0)))
    analog_labels: list[str] = field(default_factory=list)
    analog_rate: float = 0.0
    first_frame: int = 1
    events: list[tuple[str, str, float]] = field(default_factory=list)
    units: str = "mm"
    metadata: dict[str, Any] = field(default_factory=dict)

    @property
    def n_frames(self) -> int:
        """Number of frames F."""
        return int(self.points.shape[0])

    @property
    def n_markers(self) -> int:
        """Number of markers M."""
        return int(self.points.shape[1])

    @property
    def analog_per_frame(self) -> int:
        """Analog samples per channel and frame (0 without analog channels)."""
        if self.analog.shape[1] == 0 or self.point_rate <= 0:
            return 0
        return round(self.analog_rate / self.point_rate)

    def check(self, path: str | Path) -> None:
        """Raise :class:`FileFormatError` naming ``path`` if the arrays are inconsistent."""
        pts = self.points
        if pts.ndim != 3 or pts.shape[2] != 3:
            raise FileFormatError(path, f"points must have shape (F, M, 3), not {pts.shape}")
        if len(self.labels) != pts.shape[1]:
            raise FileFormatError(path, f"{len(self.labels)} labels for {pts.shape[1]} markers")
        if not self.point_rate > 0:
            raise FileFormatError(path, f"point rate must be positive, not {self.point_rate}")
        if self.analog.ndim != 2:
            raise FileFormatError(path, f"analog must have shape (S, A), not {self.analog.shape}")
        n_channels = self.analog.shape[1]
        if n_channels:
            if len(self.analog_labels) != n_channels:
                raise FileFormatError(
                    path, f"{len(self.analog_labels)} analog labels for {n_channels} channels"
                )
            ratio = self.analog_rate / self.point_rate
            if ratio < 1 or abs(ratio - round(ratio)) > 1e-9:
                raise FileFormatError(
                    path,
                    f"analog rate {self.analog_rate} Hz is not a whole multiple"
                    f" of the point rate {self.point_rate} Hz",
                )
            if self.analog.shape[0] != pts.shape[0] * round(ratio):
                raise FileFormatError(
                    path,
                    f"{self.analog.shape[0]} analog samples for {pts.shape[0]} frames"
                    f" at {round(ratio)} samples per frame",
                )
