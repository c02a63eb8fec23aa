"""Bytes of Qualisys' QTM real-time protocol, as the simulated QTM server writes them.

Written from ``docs/protocols/qualisys.md`` (Qualisys' protocol, version 1.25,
little-endian), not from the driver: every packet is ``uint32 size`` (header
included), ``uint32 type``, then the body. The server reads commands with
:class:`CommandReader` and writes replies, events and data packets with the
``*_packet`` functions here.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

F64 = npt.NDArray[np.float64]

#: Packet types (qualisys.md §2).
ERROR, COMMAND, XML, DATA, NO_MORE_DATA, EVENT = 0, 1, 2, 3, 4, 6
#: Component types (qualisys.md §4) by the name a client asks for them with.
COMPONENTS = {"3d": 1, "3dnolabels": 2, "6d": 5, "2d": 7}
#: Events (qualisys.md §5).
EV_CONNECTED, EV_CONNECTION_CLOSED, EV_CAPTURE_STARTED, EV_CAPTURE_STOPPED = 1, 2, 3, 4

_HEADER = struct.Struct("<II")
_DATA_HEAD = struct.Struct("<qII")
_COUNTS = struct.Struct("<Ihh")
#: Largest command packet the server accepts (a guard against a garbled size).
MAX_COMMAND = 1 << 20


def packet(kind: int, body: bytes) -> bytes:
    """One packet: header (size including itself, type) then ``body``."""
    return _HEADER.pack(_HEADER.size + len(body), kind) + body


def text_packet(kind: int, text: str) -> bytes:
    """A Command, Error or XML packet: ``text`` and its NUL."""
    return packet(kind, text.encode() + b"\0")


def event_packet(event: int) -> bytes:
    """An Event packet: one byte."""
    return packet(EVENT, bytes([event]))


def _component(kind: int, body: bytes) -> bytes:
    return _HEADER.pack(_HEADER.size + len(body), kind) + body


def component_3d(markers: F64) -> bytes:
    """The 3D component: labelled markers (M, 3) mm, NaN where not seen."""
    xyz = np.ascontiguousarray(markers, dtype="<f4").reshape(-1, 3)
    return _component(COMPONENTS["3d"], _COUNTS.pack(len(xyz), 0, 0) + xyz.tobytes())


def component_3d_no_labels(markers: F64) -> bytes:
    """The 3DNoLabels component: the markers seen, id = label index + 1."""
    xyz = np.asarray(markers, dtype=np.float64).reshape(-1, 3)
    seen = np.flatnonzero(np.isfinite(xyz).all(axis=1))
    rec = np.zeros(len(seen), dtype=[("xyz", "<f4", 3), ("id", "<u4")])
    rec["xyz"] = xyz[seen]
    rec["id"] = seen + 1
    return _component(COMPONENTS["3dnolabels"], _COUNTS.pack(len(seen), 0, 0) + rec.tobytes())


def component_6d(positions: F64, rotations: F64) -> bytes:
    """The 6D component: bodies' positions (B, 3) mm and rotations (B, 3, 3), the matrix
    sent column by column (qualisys.md §4)."""
    pos = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    rot = np.asarray(rotations, dtype=np.float64).reshape(-1, 3, 3)
    cols = np.transpose(rot, (0, 2, 1)).reshape(-1, 9)
    body = np.concatenate([pos, cols], axis=1).astype("<f4")
    return _component(COMPONENTS["6d"], struct.pack("<ihh", len(pos), 0, 0) + body.tobytes())


def component_2d(cameras: Sequence[tuple[npt.NDArray[np.int32], npt.NDArray[np.uint16]]]) -> bytes:
    """The 2D component: per camera the markers' (K, 2) int32 sub-pixel coordinates and
    (K, 2) uint16 diameters."""
    parts = [_COUNTS.pack(len(cameras), 0, 0)]
    for xy, diam in cameras:
        rec = np.zeros(len(xy), dtype=[("xy", "<i4", 2), ("d", "<u2", 2)])
        rec["xy"] = xy
        rec["d"] = diam
        parts.append(struct.pack("<iB", len(xy), 0) + rec.tobytes())
    return _component(COMPONENTS["2d"], b"".join(parts))


def data_packet(timestamp_us: int, frame: int, components: Sequence[bytes]) -> bytes:
    """A Data packet: timestamp (µs), frame number, then the components."""
    head = _DATA_HEAD.pack(timestamp_us, frame & 0xFFFFFFFF, len(components))
    return packet(DATA, head + b"".join(components))


@dataclass(frozen=True)
class ClientPacket:
    """A packet a client sent: its type and its text (NUL stripped)."""

    kind: int
    text: str


class CommandReader:
    """Packets out of the bytes a client sends, from any split of them."""

    def __init__(self) -> None:
        self._buf = bytearray()

    def feed(self, data: bytes) -> list[ClientPacket]:
        """The packets completed by ``data``.

        Raises
        ------
        ValueError
            If a header claims a size below 8 or above :data:`MAX_COMMAND`.
        """
        self._buf += data
        out: list[ClientPacket] = []
        while len(self._buf) >= _HEADER.size:
            size, kind = _HEADER.unpack_from(self._buf)
            if not _HEADER.size <= size <= MAX_COMMAND:
                raise ValueError(f"a packet of {size} bytes (type {kind})")
            if len(self._buf) < size:
                break
            body = bytes(self._buf[_HEADER.size : size]).rstrip(b"\0")
            del self._buf[:size]
            out.append(ClientPacket(kind, body.decode("utf-8", "replace")))
        return out
