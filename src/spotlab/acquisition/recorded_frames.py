"""The recorded frames that session time is computed from: a device stream's and a timer's.

The inputs of :func:`spotlab.acquisition.timebase.session_timebase` and of the pairing
of frames with pulse edges (:mod:`spotlab.acquisition._frame_pulses`), kept apart from
both so that neither imports the other.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from spotlab.core.streams import StreamSpec

__all__ = ["DeviceFrames", "TimerFrames"]

I64 = npt.NDArray[np.int64]
B = npt.NDArray[np.bool_]


@dataclass(frozen=True)
class DeviceFrames:
    """The frames of one recorded device stream (input of :func:`session_timebase`).

    Attributes
    ----------
    name : str
        Stream name.
    seq : ndarray of int64, shape (F,)
        Unwrapped sequence numbers (a new run starts at a new multiple of 65536).
    ticks : ndarray of int64, shape (F,)
        Unwrapped device ticks.
    arrival_ns : ndarray of int64, shape (F,)
        Host arrival stamps, ns.
    spec : StreamSpec
        The stream's spec (tick rate, frame rate, slots).
    """

    name: str
    seq: I64
    ticks: I64
    arrival_ns: I64
    spec: StreamSpec


@dataclass(frozen=True)
class TimerFrames:
    """A recorded timer stream: its frames and the edges they carried.

    Attributes
    ----------
    name : str
        Stream name.
    seq, ticks, arrival_ns : ndarray of int64, shape (F,)
        Timer frames: seq, counter at the frame (10 MHz), host arrival (ns).
    edge_input, edge_index, edge_tick : ndarray of int64, shape (K,)
        Edges: channel, edge number of the channel, counter at the edge.
    edge_rising : ndarray of bool, shape (K,)
        Rising edge.
    """

    name: str
    seq: I64
    ticks: I64
    arrival_ns: I64
    edge_input: I64
    edge_index: I64
    edge_tick: I64
    edge_rising: B
