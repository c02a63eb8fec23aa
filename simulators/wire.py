"""Device side of the MCS-1 bytes: replies, stream frames and the SPX payload.

Written from ``docs/protocols/mcs1.md`` and ``docs/protocols/selspot.md``, not
from the driver's codec. Everything here is a pure function of its arguments,
so the golden byte vectors of both specs can be produced and checked directly.

All multi-byte fields are little-endian; checksums are CRC-16/CCITT-FALSE
(:func:`spotlab.core.crc16`).
"""

from __future__ import annotations

import struct

import numpy as np
import numpy.typing as npt

from spotlab.core.crc import crc16, crc16_hex

SYNC = b"\xa5\x5a"
FRAME_SPX = 0x01
FRAME_EVENT = 0x7F
PROTOCOL_VERSION = 1
HEADER_FLAG_OVERRUN = 0x01
HEADER_FLAG_CLOCK_RESYNCED = 0x02
HEADER_FLAG_SIMULATED = 0x04
MAX_PAYLOAD = 4096
INVALID = 0xFFF
BANNER = b"RESET7DB2\r"

#: ``COMM:<c>`` codes and their baud rates (MCS-1 §1).
BAUD_RATES: dict[int, int] = {
    0: 9_600,
    1: 14_400,
    2: 19_200,
    3: 38_400,
    4: 57_600,
    5: 115_200,
    6: 921_600,
    7: 1_000_000,
    8: 2_000_000,
    9: 3_000_000,
}
RESET_BAUD = 9_600

# Status word bits (MCS-1 §5).
STATUS_COMM_SYNC = 0x01
STATUS_AMBIENT_HIGH = 0x02
STATUS_BAD_CRC = 0x04
STATUS_RECOVERED = 0x08
STATUS_HARDWARE_FAULT = 0x10
STATUS_CONFIG_CHANGED = 0x20
STATUS_FIFO_OVERFLOW = 0x40
STATUS_EXT_SYNC_LOST = 0x80

# Record flag bits (SPX §4).
FLAG_VALID = 0x01
FLAG_SATURATED = 0x02
FLAG_LOW_SIGNAL = 0x04
FLAG_AMBIENT_HIGH = 0x08
FLAG_NEAR_EDGE = 0x10
FLAG_SLOT_OVERRUN = 0x20
FLAG_AGC_LIMIT = 0x40

_HEADER = struct.Struct("<2sBBHH")
_PREFIX = struct.Struct("<IIHHHBB")
SPX_HEADER_BYTES = 16
SPX_RECORD_BYTES = 5
FRAME_OVERHEAD = 12


def reply(text: str) -> bytes:
    """A reply as sent outside a stream: ``TEXT`` + CRC (4 hex digits) + ``\\r``.

    Parameters
    ----------
    text : str
        ASCII reply text, e.g. ``"OKAY"`` or ``"ERROR80"``.

    Returns
    -------
    bytes
        The reply bytes, e.g. ``b"OKAY26CF\\r"``.
    """
    return (text + crc16_hex(text) + "\r").encode("ascii")


def command(text: str) -> bytes:
    """A host command in CRC form, ``VERB:ARGS`` + CRC + ``\\r`` (for tests and tools)."""
    return (text + crc16_hex(text) + "\r").encode("ascii")


def header_flags(*, simulated: bool = False, overrun: bool = False, resynced: bool = False) -> int:
    """The version-and-flags byte: protocol version 1 in the high nibble, flag bits below."""
    flags = PROTOCOL_VERSION << 4
    if overrun:
        flags |= HEADER_FLAG_OVERRUN
    if resynced:
        flags |= HEADER_FLAG_CLOCK_RESYNCED
    if simulated:
        flags |= HEADER_FLAG_SIMULATED
    return flags


def frame(frame_type: int, seq: int, payload: bytes, flags: int = PROTOCOL_VERSION << 4) -> bytes:
    """A stream frame: sync, type, flags, seq, len, header CRC, payload, payload CRC.

    Parameters
    ----------
    frame_type : int
        ``0x01`` SPX data, ``0x7F`` event, ...
    seq : int
        Sequence number; taken modulo 2**16.
    payload : bytes
        At most 4096 bytes.
    flags : int, optional
        The version-and-flags byte (see :func:`header_flags`).

    Returns
    -------
    bytes
        ``len(payload) + 12`` bytes.

    Raises
    ------
    ValueError
        If the payload is longer than 4096 bytes.
    """
    if len(payload) > MAX_PAYLOAD:
        raise ValueError(
            f"payload of {len(payload)} bytes exceeds the MCS-1 limit of {MAX_PAYLOAD}"
        )
    head = _HEADER.pack(SYNC, frame_type, flags, seq & 0xFFFF, len(payload))
    return b"".join(
        (
            head,
            crc16(head).to_bytes(2, "little"),
            payload,
            crc16(payload).to_bytes(2, "little"),
        )
    )


def event_frame(reply_bytes: bytes, flags: int = PROTOCOL_VERSION << 4) -> bytes:
    """An event frame (type ``0x7F``, seq 0) holding a reply exactly as sent outside a stream."""
    return frame(FRAME_EVENT, 0, reply_bytes, flags)


def spx_frame_length(n_leds: int, n_cams: int) -> int:
    """Bytes of a whole SPX data frame: ``28 + 5 N C``."""
    return FRAME_OVERHEAD + SPX_HEADER_BYTES + SPX_RECORD_BYTES * n_leds * n_cams


def spx_payload(
    frame_no: int,
    tick: int,
    status: int,
    slot_us: int,
    x: npt.ArrayLike,
    y: npt.ArrayLike,
    intensity: npt.ArrayLike,
    flags: npt.ArrayLike,
) -> bytes:
    """The payload of an SPX data frame (SPX §4), vectorised over LEDs and cameras.

    Parameters
    ----------
    frame_no : int
        Frame periods since ``START:``; taken modulo 2**32.
    tick : int
        Device clock in µs at the start of the first slot; taken modulo 2**32.
    status : int
        Status word (MCS-1 §5).
    slot_us : int
        Slot period in µs.
    x, y : array_like of int, shape (N, C)
        Detector coordinates 0-4094, or ``0xFFF`` when not valid.
    intensity : array_like of int, shape (N, C)
        Intensity 0-255.
    flags : array_like of int, shape (N, C)
        Record flags.

    Returns
    -------
    bytes
        ``16 + 5 N C`` bytes, records LED-major (LED 0 camera 0, LED 0 camera 1, ...).
    """
    xa = np.asarray(x, dtype=np.uint32)
    if xa.ndim != 2:
        raise ValueError(f"x must have shape (N, C), got {xa.shape}")
    n_leds, n_cams = xa.shape
    word = (xa & 0xFFF) | ((np.asarray(y, dtype=np.uint32) & 0xFFF) << 12)
    rec = np.empty((n_leds, n_cams, SPX_RECORD_BYTES), dtype=np.uint8)
    rec[..., 0] = word & 0xFF
    rec[..., 1] = (word >> 8) & 0xFF
    rec[..., 2] = (word >> 16) & 0xFF
    rec[..., 3] = np.asarray(intensity, dtype=np.uint8)
    rec[..., 4] = np.asarray(flags, dtype=np.uint8)
    prefix = _PREFIX.pack(
        frame_no & 0xFFFFFFFF,
        tick & 0xFFFFFFFF,
        status & 0xFFFF,
        (n_leds * n_cams) & 0xFFFF,
        slot_us & 0xFFFF,
        n_leds & 0xFF,
        n_cams & 0xFF,
    )
    return prefix + rec.tobytes()
