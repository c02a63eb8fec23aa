"""Device side of the TMR bytes: timer data frame payloads and LTC timecode (timer.md).

Written from ``docs/protocols/timer.md``, not from the driver's codec. Pure
functions of their arguments, so that the spec's golden byte vectors can be
produced and checked directly. Framing (sync, header, CRCs) is
:func:`spotlab.simulators.wire.frame`.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from dataclasses import dataclass

from spotlab.simulators import wire

FRAME_TMR = 0x04
#: Timer counter rate: 10 MHz (100 ns ticks).
TICK_HZ = 10_000_000
TICKS_PER_US = 10
HEADER_BYTES = 32
RECORD_BYTES = 12
MAX_INPUTS = 8
MAX_OUTPUTS = 4
MAX_SLOTS = 64
#: Channel byte bit 7: the record is a pulse the timer emitted on an output.
CHANNEL_OUTPUT = 0x80
EDGE_RISING = 0x01
TC_ON = 0x01
TC_DROP_FRAME = 0x02

_PREFIX = struct.Struct("<IIHHqHHBBBBBBBB")
_RECORD = struct.Struct("<qBBH")


@dataclass(frozen=True)
class EdgeRecord:
    """One captured input edge or emitted output pulse, as the frame carries it.

    Attributes
    ----------
    tick : int
        Timer counter (10 MHz ticks) at the edge; sent as 64 bits.
    channel : int
        Input number 0-7, or ``0x80 | output`` for an emitted pulse.
    rising : bool
        Rising edge (False: falling).
    count : int
        Edges of this channel since ``START:`` before this one (sent modulo 2**16).
    """

    tick: int
    channel: int
    rising: bool
    count: int


@dataclass(frozen=True)
class Timecode:
    """SMPTE LTC fields of a timer frame.

    Attributes
    ----------
    fps : int
        Nominal rate 24, 25 or 30.
    drop_frame : bool
        29.97 Hz with drop-frame numbering (``fps`` is then 30).
    hh, mm, ss, ff : int
        Hours, minutes, seconds, frames.
    """

    fps: int
    drop_frame: bool
    hh: int
    mm: int
    ss: int
    ff: int


def tmr_frame_length(n_slots: int) -> int:
    """Bytes of a whole timer data frame: ``44 + 12 E``."""
    return wire.FRAME_OVERHEAD + HEADER_BYTES + RECORD_BYTES * n_slots


def tmr_payload(
    frame_no: int,
    tick: int,
    status: int,
    armed: int,
    edges_lost: int,
    n_slots: int,
    edges: Sequence[EdgeRecord],
    timecode: Timecode | None = None,
) -> bytes:
    """The payload of a timer data frame (timer.md §4).

    Parameters
    ----------
    frame_no : int
        Frame periods since ``START:``; modulo 2**32.
    tick : int
        Timer counter in 10 MHz ticks at the frame's instant (64 bits, two's
        complement); the MCS-1 prefix carries ``tick // 10`` modulo 2**32.
    status : int
        Status word (MCS-1 §5).
    armed : int
        Input arming mask: bit ``2i`` rising, bit ``2i + 1`` falling edges of input ``i``.
    edges_lost : int
        Edges dropped for lack of room since ``START:``; modulo 2**16.
    n_slots : int
        Edge slots per frame ``E`` (1-64).
    edges : sequence of EdgeRecord
        At most ``n_slots`` records, in capture order.
    timecode : Timecode, optional
        LTC fields; None when timecode is off.

    Returns
    -------
    bytes
        ``32 + 12 E`` bytes; unused slots are zero.

    Raises
    ------
    ValueError
        If there are more edges than slots.
    """
    if len(edges) > n_slots:
        raise ValueError(f"{len(edges)} edges do not fit {n_slots} slots")
    tc = timecode
    tc_flags = 0 if tc is None else TC_ON | (TC_DROP_FRAME if tc.drop_frame else 0)
    head = _PREFIX.pack(
        frame_no & 0xFFFFFFFF,
        (tick // TICKS_PER_US) & 0xFFFFFFFF,
        status & 0xFFFF,
        len(edges),
        _signed64(tick),
        armed & 0xFFFF,
        edges_lost & 0xFFFF,
        n_slots,
        tc_flags,
        0 if tc is None else tc.fps,
        0 if tc is None else tc.hh,
        0 if tc is None else tc.mm,
        0 if tc is None else tc.ss,
        0 if tc is None else tc.ff,
        0,
    )
    body = b"".join(
        _RECORD.pack(_signed64(e.tick), e.channel, EDGE_RISING if e.rising else 0, e.count & 0xFFFF)
        for e in edges
    )
    return head + body + bytes(RECORD_BYTES * (n_slots - len(edges)))


def _signed64(value: int) -> int:
    """``value`` modulo 2**64, as the signed 64-bit integer with those bits."""
    value &= (1 << 64) - 1
    return value - (1 << 64) if value >= 1 << 63 else value


#: LTC frames per day for each (fps, drop_frame).
FRAMES_PER_DAY = {(24, False): 2_073_600, (25, False): 2_160_000, (30, False): 2_592_000,
                  (30, True): 2_589_408}  # fmt: skip


def ltc_frames(tick: int, fps: int, drop_frame: bool) -> int:
    """LTC frames counted since timer tick 0 at ``tick`` (floor), for the frame rate.

    29.97 Hz drop-frame runs at 30000/1001 frames per second; the others at ``fps``.
    """
    num, den = (30_000, 1001) if drop_frame else (fps, 1)
    return (tick * num) // (den * TICK_HZ)


def timecode_at(tick: int, fps: int, drop_frame: bool) -> Timecode:
    """The LTC label of the frame running at timer ``tick`` (timer.md §5).

    The label counts from 00:00:00:00 at tick 0 and wraps every 24 h. Drop-frame
    numbering skips labels ``:00`` and ``:01`` at the start of every minute not
    divisible by ten (SMPTE ST 12-1).
    """
    if (fps, drop_frame) not in FRAMES_PER_DAY:
        raise ValueError(f"no LTC rate {fps} fps (drop-frame {drop_frame})")
    n = ltc_frames(tick, fps, drop_frame) % FRAMES_PER_DAY[(fps, drop_frame)]
    if drop_frame:
        tens, rest = divmod(n, 17_982)  # frames per 10 minutes
        n += 18 * tens + (2 * ((rest - 2) // 1798) if rest >= 2 else 0)
    ff = n % fps
    seconds = n // fps
    return Timecode(fps, drop_frame, seconds // 3600 % 24, seconds // 60 % 60, seconds % 60, ff)
