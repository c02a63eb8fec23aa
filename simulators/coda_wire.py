"""Device side of the CSX bytes: scanner data frame payloads (docs/protocols/coda.md).

Written from ``docs/protocols/coda.md``, not from the driver's codec. Pure
functions of their arguments, so that the spec's golden byte vectors can be
produced and checked directly. Framing (sync, header, CRCs) is
:func:`spotlab.simulators.wire.frame`.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Sequence
from dataclasses import dataclass

from spotlab.simulators import wire

FRAME_CSX = 0x02
HEADER_BYTES = 16
#: Extra record slots beyond the marker table (ghosts, aliased pairs).
SPARE_SLOTS = 4
MAX_MARKERS = 56
#: Angle counts over the 40 degree field of each mirror; count 8000 is straight ahead.
COUNTS = 16_000
FOV_DEG = 40.0
CENTRE_COUNT = 8_000
NOT_SEEN = 0xFFFF
#: Output modes (``OUT:``) by name, and their codes in the frame header.
MODES = {"3D": 1, "RAW": 2, "BOTH": 3}
MODE_3D, MODE_RAW = 1, 2
#: Record flag bits (coda.md §4).
F_3D_VALID, F_SEEN_A, F_SEEN_B, F_SEEN_C = 0x01, 0x02, 0x04, 0x08
F_COLOUR_AMBIGUOUS, F_ALIASED, F_GHOST = 0x10, 0x20, 0x40
#: The eight colours of a marker's two bands, in code order.
COLOURS = "ROYGCBVW"
#: (rate limit mHz, markers): the most markers a scan rate serves without aliasing.
MARKER_LIMITS = ((100_000, 56), (200_000, 28), (400_000, 12), (800_000, 6))

_HEAD = struct.Struct("<IIHHBBBB")
_ID = struct.Struct("<BB")
_XYZ = struct.Struct("<iii")
_RAW = struct.Struct("<HHHHHH")


def colour_id(code: str) -> int:
    """The marker ID (1-56) of a two-band colour code such as ``"RO"``; ValueError if none."""
    if len(code) != 2 or code[0] not in COLOURS or code[1] not in COLOURS or code[0] == code[1]:
        raise ValueError(f"no marker colour code {code!r}")
    i, j = COLOURS.index(code[0]), COLOURS.index(code[1])
    return 7 * i + (j if j < i else j - 1) + 1


def id_colour(marker_id: int) -> str:
    """The colour code of a marker ID (1-56)."""
    if not 1 <= marker_id <= MAX_MARKERS:
        raise ValueError(f"marker IDs are 1-{MAX_MARKERS}, got {marker_id}")
    i, r = divmod(marker_id - 1, 7)
    j = r if r < i else r + 1
    return COLOURS[i] + COLOURS[j]


def marker_limit(rate_mhz: int) -> int:
    """Markers the scan rate serves before IDs alias (coda.md §1)."""
    for top, n in MARKER_LIMITS:
        if rate_mhz <= top:
            return n
    return MARKER_LIMITS[-1][1]


def record_bytes(mode: int) -> int:
    """Bytes of one marker record in output mode ``mode`` (1 3D, 2 RAW, 3 BOTH)."""
    return 2 + (12 if mode & MODE_3D else 0) + (12 if mode & MODE_RAW else 0)


def csx_frame_length(n_markers: int, mode: int) -> int:
    """Bytes of a whole data frame: ``12 + 16 + (M + 4) R``."""
    return wire.FRAME_OVERHEAD + HEADER_BYTES + (n_markers + SPARE_SLOTS) * record_bytes(mode)


def angle_count(angle_rad: float) -> int:
    """The count of an angle (rad), rounded; :data:`NOT_SEEN` outside the field or NaN."""
    if not math.isfinite(angle_rad):
        return NOT_SEEN
    c = round(CENTRE_COUNT + math.degrees(angle_rad) * COUNTS / FOV_DEG)
    return c if 0 <= c < COUNTS else NOT_SEEN


@dataclass(frozen=True)
class MarkerRecord:
    """One detection as the frame carries it (coda.md §4).

    Attributes
    ----------
    marker_id : int
        Colour code ID 1-56 as read (0: not identified).
    flags : int
        Record flag bits.
    xyz_cmm : tuple of int
        x, y, z in 0.01 mm (scanner frame); ignored in RAW mode.
    counts : tuple of int
        alpha_A, alpha_B, beta counts (0xFFFF not seen); ignored in 3D mode.
    dt_us : tuple of int
        Crossing instants of mirrors A, B, C in µs after the scan start (0xFFFF not seen).
    """

    marker_id: int
    flags: int
    xyz_cmm: tuple[int, int, int] = (0, 0, 0)
    counts: tuple[int, int, int] = (NOT_SEEN, NOT_SEEN, NOT_SEEN)
    dt_us: tuple[int, int, int] = (NOT_SEEN, NOT_SEEN, NOT_SEEN)


def csx_payload(
    frame_no: int,
    tick_us: int,
    status: int,
    mode: int,
    n_markers: int,
    limit: int,
    records: Sequence[MarkerRecord],
) -> bytes:
    """The payload of a scanner data frame (coda.md §3).

    Parameters
    ----------
    frame_no, tick_us, status : int
        MCS-1 prefix (tick: device µs at the scan start, modulo 2**32).
    mode : int
        1 3D, 2 RAW, 3 BOTH.
    n_markers : int
        Markers in the table ``M``; the frame has ``M + 4`` slots.
    limit : int
        Marker limit of the scan rate.
    records : sequence of MarkerRecord
        At most ``M + 4``.

    Returns
    -------
    bytes
        ``16 + (M + 4) R`` bytes; unused slots are zero.
    """
    slots = n_markers + SPARE_SLOTS
    if len(records) > slots:
        raise ValueError(f"{len(records)} records do not fit {slots} slots")
    head = _HEAD.pack(
        frame_no & 0xFFFFFFFF, tick_us & 0xFFFFFFFF, status & 0xFFFF, len(records),
        mode, slots, n_markers, limit,
    )  # fmt: skip
    body = bytearray()
    for r in records:
        body += _ID.pack(r.marker_id, r.flags)
        if mode & MODE_3D:
            body += _XYZ.pack(*r.xyz_cmm)
        if mode & MODE_RAW:
            body += _RAW.pack(*r.counts, *r.dt_us)
    return head + bytes(body) + bytes(record_bytes(mode) * (slots - len(records)))


def csx_frame(seq: int, payload: bytes, flags: int = wire.PROTOCOL_VERSION << 4) -> bytes:
    """The whole data frame of ``payload`` (``flags``: the header's version and flags byte)."""
    return wire.frame(FRAME_CSX, seq, payload, flags)
