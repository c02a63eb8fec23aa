"""Frames and blocks of frames: numpy arrays, NaN for missing values.

A driver delivers :class:`FrameBlock` objects — all fields stacked along a
leading frame axis — so that no per-marker Python object sits on the hot path.
:class:`Frame` is one row of a block, for convenience at the edges.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from spotlab.core.errors import ConfigurationError
from spotlab.core.streams import StreamSpec

I64 = npt.NDArray[np.int64]
F64 = npt.NDArray[np.float64]
U8 = npt.NDArray[np.uint8]
U16 = npt.NDArray[np.uint16]


@dataclass(frozen=True)
class Frame:
    """One frame of one stream.

    Attributes
    ----------
    seq : int
        Unwrapped sequence number.
    ticks : int
        Device timestamp, unwrapped, in device ticks (see ``StreamSpec.tick_hz``).
    arrival_ns : int
        Host monotonic time (``time.monotonic_ns``) when the frame's last byte arrived.
    data : ndarray of float64, shape (M, S, V)
        Values per marker, sensor and value name; NaN where missing.
    flags : ndarray of uint8, shape (M, S)
        Per-value quality flags (device-specific bits, see the protocol spec).
    status : int
        Device status word of the frame.
    """

    seq: int
    ticks: int
    arrival_ns: int
    data: F64
    flags: U8
    status: int


@dataclass(frozen=True)
class FrameBlock:
    """Consecutive frames of one stream, stacked along axis 0.

    Attributes
    ----------
    seq : ndarray of int64, shape (F,)
        Unwrapped sequence numbers.
    ticks : ndarray of int64, shape (F,)
        Unwrapped device timestamps in device ticks.
    arrival_ns : ndarray of int64, shape (F,)
        Host monotonic arrival time of each frame's last byte, in ns.
    data : ndarray of float64, shape (F, M, S, V)
        Values; NaN where missing.
    flags : ndarray of uint8, shape (F, M, S)
        Quality flags.
    status : ndarray of uint16, shape (F,)
        Device status words.
    """

    seq: I64
    ticks: I64
    arrival_ns: I64
    data: F64
    flags: U8
    status: U16

    def __post_init__(self) -> None:
        n = self.seq.shape[0]
        for name in ("ticks", "arrival_ns", "status"):
            if getattr(self, name).shape != (n,):
                raise ConfigurationError(f"FrameBlock.{name} must have shape ({n},)")
        if self.data.ndim != 4 or self.data.shape[0] != n:
            raise ConfigurationError(f"FrameBlock.data must have shape ({n}, M, S, V)")
        if self.flags.shape != self.data.shape[:3]:
            raise ConfigurationError("FrameBlock.flags must have shape (F, M, S)")

    def __len__(self) -> int:
        return int(self.seq.shape[0])

    def frame(self, i: int) -> Frame:
        """Frame ``i`` of the block as a :class:`Frame`."""
        return Frame(
            seq=int(self.seq[i]),
            ticks=int(self.ticks[i]),
            arrival_ns=int(self.arrival_ns[i]),
            data=self.data[i],
            flags=self.flags[i],
            status=int(self.status[i]),
        )

    @classmethod
    def empty(cls, n_markers: int, n_sensors: int, n_values: int) -> FrameBlock:
        """A block of zero frames with the given marker, sensor and value counts."""
        return cls(
            seq=np.zeros(0, np.int64),
            ticks=np.zeros(0, np.int64),
            arrival_ns=np.zeros(0, np.int64),
            data=np.zeros((0, n_markers, n_sensors, n_values)),
            flags=np.zeros((0, n_markers, n_sensors), np.uint8),
            status=np.zeros(0, np.uint16),
        )

    @classmethod
    def concat(cls, blocks: Sequence[FrameBlock]) -> FrameBlock:
        """Join blocks of the same stream along the frame axis.

        Raises
        ------
        ConfigurationError
            If ``blocks`` is empty or the blocks' marker, sensor or value counts differ.
        """
        if not blocks:
            raise ConfigurationError("cannot join an empty list of frame blocks")
        shapes = {b.data.shape[1:] for b in blocks}
        if len(shapes) > 1:
            raise ConfigurationError(f"frame blocks of different shapes cannot be joined: {shapes}")
        return cls(
            seq=np.concatenate([b.seq for b in blocks]),
            ticks=np.concatenate([b.ticks for b in blocks]),
            arrival_ns=np.concatenate([b.arrival_ns for b in blocks]),
            data=np.concatenate([b.data for b in blocks]),
            flags=np.concatenate([b.flags for b in blocks]),
            status=np.concatenate([b.status for b in blocks]),
        )

    def sample_ticks(self, spec: StreamSpec) -> F64:
        """Device time of every marker's sample, in ticks.

        For time-multiplexed devices the sample of marker ``k`` is taken at
        frame time + (k + 1/2) * slot, not at the frame time.

        Parameters
        ----------
        spec : StreamSpec
            The stream's description (slot period and tick rate).

        Returns
        -------
        ndarray of float64, shape (F, M)
            Sample times in device ticks (fractional).
        """
        offsets_ticks = spec.sample_offsets_ns().astype(np.float64) * spec.tick_hz / 1e9
        return self.ticks.astype(np.float64)[:, None] + offsets_ticks[None, :]
