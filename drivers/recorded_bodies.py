"""What the 6-DOF families share: rigid-body poses per frame, and the decoders of one
recorded stream (the journal holds the systems' packets raw; poses are decoded on
request, not as blocks).

:class:`RigidBodies` is the one shape of a recording's rigid bodies for every family
that streams them (Qualisys' 6D component, NatNet's rigid bodies).
:func:`stream_decoders` replays a recording and builds a decoder only for the stream
asked for, so a family can collect what its decoder kept of that stream.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, TypeVar

import numpy as np
import numpy.typing as npt

from spotlab.acquisition.replay import replay
from spotlab.core.errors import RecordingError
from spotlab.core.frames import FrameBlock
from spotlab.core.stats import LinkStats
from spotlab.core.wire import StreamDecoder

__all__ = ["RigidBodies", "stream_decoders"]

F64 = npt.NDArray[np.float64]
D = TypeVar("D", bound=StreamDecoder)


@dataclass(frozen=True)
class RigidBodies:
    """Rigid bodies per frame of one stream.

    Attributes
    ----------
    stream : str
        Stream name.
    names : tuple of str, length B
        Body names, as the system describes them.
    seq : ndarray of int64, shape (F,)
        Sequence numbers (the system's frame numbers) of the frames that carried poses.
    positions : ndarray, shape (F, B, 3)
        Body origins in mm; NaN where the system did not find (track) the body.
    rotations : ndarray, shape (F, B, 3, 3)
        Body to world rotations (columns: the body's axes in the world).
    """

    stream: str
    names: tuple[str, ...]
    seq: npt.NDArray[np.int64]
    positions: F64
    rotations: F64


def stream_decoders(
    path: str | os.PathLike[str],
    family: str,
    stream: str,
    make: Callable[[dict[str, Any]], D],
) -> list[D]:
    """Replay a recording, decoding only stream ``stream`` of ``family``.

    Parameters
    ----------
    path : path-like
        The recording.
    family, stream : str
        Which stream (its family and its name in the recording).
    make : callable
        The stream's decoder from its metadata, once per run of the stream (a stream
        restarted within a recording has several).

    Returns
    -------
    list
        The decoders made, in order, after the replay fed them.

    Raises
    ------
    RecordingError
        If the recording has no such stream.
    """
    decoders: list[D] = []

    def factory(meta: dict[str, Any]) -> StreamDecoder:
        spec = meta.get("spec") or {}
        if meta.get("family") != family or spec.get("name") != stream:
            return _Ignored()
        dec = make(meta)
        decoders.append(dec)
        return dec

    for _ in replay(path, factory):
        pass
    if not decoders:
        raise RecordingError(f"{os.fspath(path)} holds no {family} stream named {stream!r}")
    return decoders


class _Ignored:
    """A decoder of the other streams: they are not this replay's business."""

    def __init__(self) -> None:
        self.stats = LinkStats()

    def feed(self, data: bytes, arrival_ns: int) -> FrameBlock:
        """No frames."""
        return FrameBlock.empty(0, 1, 1)

    def mark_discontinuity(self) -> None:
        """Nothing buffered."""
