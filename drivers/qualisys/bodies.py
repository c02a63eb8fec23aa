"""The 6DOF bodies of a recorded QTM stream (the journal holds QTM's packets raw)."""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from spotlab.acquisition.replay import replay
from spotlab.core.errors import RecordingError
from spotlab.core.frames import FrameBlock
from spotlab.core.stats import LinkStats
from spotlab.core.wire import StreamDecoder
from spotlab.drivers.qualisys.decoder import QualisysDecoder, decoder_from_metadata

F64 = npt.NDArray[np.float64]


@dataclass(frozen=True)
class RigidBodies:
    """Rigid bodies per frame of one QTM stream.

    Attributes
    ----------
    stream : str
        Stream name.
    names : tuple of str, length B
        Body names, from QTM's 6D parameters.
    seq : ndarray of int64, shape (F,)
        Sequence numbers (QTM frame numbers) of the frames that carried a 6D component.
    positions : ndarray, shape (F, B, 3)
        Body origins in mm; NaN when QTM did not find the body.
    rotations : ndarray, shape (F, B, 3, 3)
        Body to world rotations (columns: the body's axes in the world).
    """

    stream: str
    names: tuple[str, ...]
    seq: npt.NDArray[np.int64]
    positions: F64
    rotations: F64


def bodies_from_recording(path: str | os.PathLike[str], stream: str = "qualisys") -> RigidBodies:
    """Decode the 6D bodies of QTM stream ``stream`` of a recording.

    Raises
    ------
    RecordingError
        If the recording has no such QTM stream.
    """
    decoders: list[QualisysDecoder] = []
    names: list[str] = []
    found = False

    def factory(meta: dict[str, Any]) -> StreamDecoder:
        nonlocal found
        spec = meta.get("spec") or {}
        if meta.get("family") != "qualisys" or spec.get("name") != stream:
            return _Null()
        found = True
        names[:] = list((spec.get("metadata") or {}).get("bodies", []))
        dec = QualisysDecoder(decoder_from_metadata(meta).n_markers, keep_bodies=True)
        decoders.append(dec)
        return dec

    for _ in replay(path, factory):
        pass
    if not found:
        raise RecordingError(f"{os.fspath(path)} holds no qualisys stream named {stream!r}")
    rows = [row for dec in decoders for row in dec.bodies]
    b = len(names)
    return RigidBodies(
        stream=stream,
        names=tuple(names),
        seq=np.array([r[0] for r in rows], dtype=np.int64),
        positions=np.array([r[1] for r in rows], dtype=np.float64).reshape(len(rows), b, 3),
        rotations=np.array([r[2] for r in rows], dtype=np.float64).reshape(len(rows), b, 3, 3),
    )


class _Null:
    """A decoder of the other streams: they are not this function's business."""

    def __init__(self) -> None:
        self.stats = LinkStats()

    def feed(self, data: bytes, arrival_ns: int) -> FrameBlock:
        """No frames."""
        return FrameBlock.empty(0, 1, 1)

    def mark_discontinuity(self) -> None:
        """Nothing buffered."""
