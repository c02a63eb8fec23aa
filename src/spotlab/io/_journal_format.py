"""Byte layout of the recording journal (see docs/journal.md).

A journal is a 16-byte file header followed by records. Every record carries
its own magic, type, stream index, payload length, host monotonic time and a
CRC-32 over its header and payload, so a reader can check each record alone
and find the next one after damage. Integers are little-endian.
"""

from __future__ import annotations

import json
import struct
import zlib
from enum import IntEnum
from typing import Any

FILE_MAGIC = b"\x89SPOTJR\n"
"""First 8 bytes of every journal. The high first byte and the line feed catch
transfers that strip the 8th bit or translate line ends."""

FORMAT_VERSION = 1
"""Version this module writes; a reader refuses any newer version."""

FILE_HEADER = struct.Struct("<8sHHI")
"""magic, version, flags (0), CRC-32 of the 12 bytes before it."""

RECORD_MAGIC = b"\xa5SJR"
"""First 4 bytes of every record, where a reader resynchronises after damage."""

RECORD_HEAD = struct.Struct("<4sBBHIq")
"""magic, type, flags (0), stream index, payload length, time in ns (20 bytes)."""

RECORD_CRC = struct.Struct("<I")
"""CRC-32 (zlib) of the 20 head bytes followed by the payload."""

RECORD_HEADER_SIZE = RECORD_HEAD.size + RECORD_CRC.size
"""24 bytes of header before each payload."""

MAX_PAYLOAD = 1 << 20
"""Largest payload of one record (1 MiB). Writers split longer wire chunks;
readers take a longer length field as damage, which bounds their memory."""

SESSION_STREAM = 0xFFFF
"""Stream index of records that concern the whole session (session META)."""

MAX_STREAMS = SESSION_STREAM
"""Streams 0 to 65534 can be declared in one journal."""


class RecordType(IntEnum):
    """What a record holds.

    META
        JSON: the session description (stream ``SESSION_STREAM``) or a stream
        declaration ``{"name": ..., "metadata": {...}}``; a later META for the
        same stream index replaces its metadata.
    RX, TX
        Raw bytes read from / written to the device, stamped on arrival / sending.
    EVENT
        JSON ``{"kind": ..., "detail": {...}}``: a link event (disconnected,
        reconnected, device_reset, ...), an error, or final link statistics.
    END
        JSON: the recording was closed cleanly; nothing follows.
    """

    META = 1
    RX = 2
    TX = 3
    EVENT = 4
    END = 5


RECORD_TYPES = frozenset(int(t) for t in RecordType)


def encode_file_header(version: int = FORMAT_VERSION) -> bytes:
    """The 16-byte file header for ``version``."""
    head = FILE_HEADER.pack(FILE_MAGIC, version, 0, 0)[:12]
    return head + RECORD_CRC.pack(zlib.crc32(head))


def encode_record(
    rtype: int, stream: int, t_ns: int, payload: bytes | bytearray | memoryview
) -> bytes:
    """One record as bytes.

    Parameters
    ----------
    rtype : int
        A :class:`RecordType`.
    stream : int
        Stream index, 0 to 65534, or ``SESSION_STREAM``.
    t_ns : int
        Host monotonic time in ns (int64).
    payload : bytes-like
        At most ``MAX_PAYLOAD`` bytes.

    Returns
    -------
    bytes
        ``RECORD_HEADER_SIZE + len(payload)`` bytes.
    """
    head = RECORD_HEAD.pack(RECORD_MAGIC, rtype, 0, stream, len(payload), t_ns)
    crc = zlib.crc32(payload, zlib.crc32(head))
    return head + RECORD_CRC.pack(crc) + bytes(payload)


def _json_default(obj: Any) -> Any:
    # Metadata and event details come from drivers and users: numpy scalars and
    # arrays, bytes, paths. Never refuse to record them; write a faithful text.
    item = getattr(obj, "item", None)
    tolist = getattr(obj, "tolist", None)
    if callable(tolist):
        return tolist()
    if callable(item):
        return item()
    if isinstance(obj, bytes | bytearray | memoryview):
        return bytes(obj).hex()
    if isinstance(obj, set | frozenset | tuple):
        return list(obj)
    return str(obj)


def encode_json(obj: Any) -> bytes:
    """UTF-8 JSON of ``obj``; values JSON cannot hold are written as text."""
    return json.dumps(obj, default=_json_default, separators=(",", ":")).encode("utf-8")
