"""The rigid bodies of a recorded NatNet stream (the journal holds Motive's frames raw).

The shape is every 6-DOF family's (:class:`spotlab.drivers.recorded_bodies.RigidBodies`):
names, frame numbers, origins in mm and body-to-world rotation matrices, so that both
families' 6D read the same; NatNet's own quaternions are kept beside them.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from spotlab.drivers.natnet.decoding import NatNetDecoder, decoder_from_metadata
from spotlab.drivers.recorded_bodies import RigidBodies, stream_decoders

F64 = npt.NDArray[np.float64]


@dataclass(frozen=True)
class NatNetBodies:
    """Rigid bodies per frame of one NatNet stream.

    Attributes
    ----------
    bodies : RigidBodies
        Names (B), frame numbers (F), positions (F, B, 3) mm and rotations (F, B, 3, 3);
        NaN where Motive did not track the body (its tracking-valid bit clear) or the
        frame did not carry it.
    quaternions : ndarray, shape (F, B, 4)
        The rotations as NatNet sent them: x, y, z, w (NaN as the positions).
    mean_error_mm : ndarray, shape (F, B)
        Motive's mean marker error of each body, mm.
    """

    bodies: RigidBodies
    quaternions: F64
    mean_error_mm: F64


def rotation_matrices(q: F64) -> F64:
    """Rotation matrices (..., 3, 3) of unit quaternions (..., 4) ordered x, y, z, w."""
    x, y, z, w = np.moveaxis(np.asarray(q, dtype=np.float64), -1, 0)
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
            np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
            np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )


def bodies_from_recording(path: str | os.PathLike[str], stream: str = "natnet") -> NatNetBodies:
    """Decode the rigid bodies of NatNet stream ``stream`` of a recording.

    Bodies are those the model descriptions named (the stream's metadata
    ``rigid_bodies``), in that order.

    Raises
    ------
    RecordingError
        If the recording has no such NatNet stream.
    """
    described: dict[str, int] = {}

    def make(meta: dict[str, Any]) -> NatNetDecoder:
        described.clear()
        described.update({str(k): int(v) for k, v in (meta.get("rigid_bodies") or {}).items()})
        return decoder_from_metadata(meta, keep_bodies=True)

    decoders = stream_decoders(path, "natnet", stream, make)
    rows = [row for dec in decoders for row in dec.bodies]
    ids = list(described.values())
    f, b = len(rows), len(ids)
    pose = np.full((f, b, 9), np.nan)
    for i, (_, by_id) in enumerate(rows):
        for j, rb_id in enumerate(ids):
            p = by_id.get(rb_id)
            if p is not None and p[8] == 1.0:
                pose[i, j] = p
    quaternions = pose[..., 3:7]
    return NatNetBodies(
        bodies=RigidBodies(
            stream=stream,
            names=tuple(described),
            seq=np.array([r[0] for r in rows], dtype=np.int64),
            positions=pose[..., 0:3] * 1000.0,
            rotations=rotation_matrices(quaternions),
        ),
        quaternions=quaternions,
        mean_error_mm=pose[..., 7] * 1000.0,
    )
