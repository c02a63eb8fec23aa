"""The 6DOF bodies of a recorded QTM stream (the journal holds QTM's packets raw)."""

from __future__ import annotations

import os
from typing import Any

import numpy as np
import numpy.typing as npt

from spotlab.drivers.qualisys.decoder import QualisysDecoder, decoder_from_metadata
from spotlab.drivers.recorded_bodies import RigidBodies, stream_decoders

F64 = npt.NDArray[np.float64]


def bodies_from_recording(path: str | os.PathLike[str], stream: str = "qualisys") -> RigidBodies:
    """Decode the 6D bodies of QTM stream ``stream`` of a recording.

    Raises
    ------
    RecordingError
        If the recording has no such QTM stream.
    """
    names: list[str] = []

    def make(meta: dict[str, Any]) -> QualisysDecoder:
        spec = meta.get("spec") or {}
        names[:] = list((spec.get("metadata") or {}).get("bodies", []))
        return QualisysDecoder(decoder_from_metadata(meta).n_markers, keep_bodies=True)

    decoders = stream_decoders(path, "qualisys", stream, make)
    rows = [row for dec in decoders for row in dec.bodies]
    b = len(names)
    return RigidBodies(
        stream=stream,
        names=tuple(names),
        seq=np.array([r[0] for r in rows], dtype=np.int64),
        positions=np.array([r[1] for r in rows], dtype=np.float64).reshape(len(rows), b, 3),
        rotations=np.array([r[2] for r in rows], dtype=np.float64).reshape(len(rows), b, 3, 3),
    )
