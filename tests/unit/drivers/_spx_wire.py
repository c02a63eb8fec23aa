"""Wire bytes of the SPX / MCS-1 protocols, written from the spec for the tests.

Deliberately independent of the driver's codec (``struct`` and ``binascii``
only), so that the tests check the driver against the spec, not against itself.
"""

from __future__ import annotations

import binascii
import struct
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np


def crc(data: bytes) -> int:
    return binascii.crc_hqx(data, 0xFFFF)


def line(text: str) -> bytes:
    """A command or reply: text + CRC (4 upper-case hex) + CR."""
    return f"{text}{crc(text.encode()):04X}\r".encode()


def mcs1_frame(ftype: int, seq: int, payload: bytes, flags: int = 0) -> bytes:
    header = b"\xa5\x5a" + struct.pack("<BBHH", ftype, 0x10 | flags, seq & 0xFFFF, len(payload))
    return header + struct.pack("<H", crc(header)) + payload + struct.pack("<H", crc(payload))


def event_frame(reply_text: str) -> bytes:
    return mcs1_frame(0x7F, 0, line(reply_text))


@dataclass
class Record:
    x: int
    y: int
    intensity: int
    flags: int

    def pack(self) -> bytes:
        w = self.x | (self.y << 12)
        return bytes([w & 0xFF, (w >> 8) & 0xFF, w >> 16, self.intensity, self.flags])


def spx_payload(
    frame_no: int,
    tick: int,
    status: int,
    records: list[Record],
    n_leds: int,
    n_cams: int,
    slot_us: int = 100,
) -> bytes:
    assert len(records) == n_leds * n_cams
    head = struct.pack(
        "<IIHHHBB",
        frame_no & 0xFFFFFFFF,
        tick & 0xFFFFFFFF,
        status,
        len(records),
        slot_us,
        n_leds,
        n_cams,
    )
    return head + b"".join(r.pack() for r in records)


@dataclass
class SpxStream:
    """A synthetic SPX stream whose every frame is known.

    Frame ``i`` has seq ``seq0 + i`` (mod 65536), frame_no ``frame_no0 + i``,
    tick ``tick0 + i * period_us`` (mod 2**32) and records derived from ``i``
    (or from ``record_fn`` when given).
    """

    n_leds: int = 3
    n_cams: int = 2
    seq0: int = 0
    frame_no0: int = 0
    tick0: int = 0
    period_us: int = 5000
    slot_us: int = 100
    frames: list[bytes] = field(default_factory=list)
    values: list[np.ndarray] = field(default_factory=list)  # (N, C, 3) expected
    flags: list[np.ndarray] = field(default_factory=list)
    record_fn: Callable[[int, int, int], Record] | None = None

    def record(self, i: int, led: int, cam: int) -> Record:
        if self.record_fn is not None:
            return self.record_fn(i, led, cam)
        k = (i * 7 + led * 13 + cam * 29) % 4096
        if k % 11 == 0:  # not seen
            return Record(0xFFF, 0xFFF, k % 7, 0x04)
        return Record(k % 4095, (k * 3) % 4095, (k * 5) % 256, 0x01 | (0x10 if k % 5 == 0 else 0))

    def make(self, count: int, status: int = 0) -> SpxStream:
        for i in range(count):
            self.append(i, status=status)
        return self

    def append(
        self, i: int, *, status: int = 0, seq: int | None = None, frame_no: int | None = None
    ) -> bytes:
        recs = [
            self.record(i, led, cam) for led in range(self.n_leds) for cam in range(self.n_cams)
        ]
        payload = spx_payload(
            self.frame_no0 + i if frame_no is None else frame_no,
            self.tick0 + i * self.period_us,
            status,
            recs,
            self.n_leds,
            self.n_cams,
            self.slot_us,
        )
        frame = mcs1_frame(0x01, self.seq0 + i if seq is None else seq, payload)
        vals = np.array(
            [
                [
                    [
                        np.nan if r.flags & 1 == 0 or r.x == 0xFFF else r.x,
                        np.nan if r.flags & 1 == 0 or r.y == 0xFFF else r.y,
                        r.intensity,
                    ]
                    for r in recs[led * self.n_cams : (led + 1) * self.n_cams]
                ]
                for led in range(self.n_leds)
            ],
            dtype=float,
        )
        self.frames.append(frame)
        self.values.append(vals)
        self.flags.append(
            np.array([r.flags for r in recs], np.uint8).reshape(self.n_leds, self.n_cams)
        )
        return frame

    @property
    def frame_len(self) -> int:
        return 28 + 5 * self.n_leds * self.n_cams


# Golden vectors, typed from docs/protocols/selspot.md §5 and mcs1.md §6.
GOLDEN_SPX_FRAME = bytes.fromhex(
    "A5 5A 01 10 FE FF 2E 00 D7 70 D2 04 00 00 00 FF FF FF 02 00 06 00 64 00 03 02"
    "00 08 80 C8 01   E8 83 BB B4 01   FF FF FF 03 04   23 C1 AB FF 03"
    "11 E0 FE 5A 11   C4 C9 5D 78 09   D3 0D"
)
GOLDEN_SPX_VALUES = [  # (led, cam, x, y, intensity, flags); None = invalid
    (0, 0, 2048, 2048, 200, 0x01),
    (0, 1, 1000, 3000, 180, 0x01),
    (1, 0, None, None, 3, 0x04),
    (1, 1, 291, 2748, 255, 0x03),
    (2, 0, 17, 4078, 90, 0x11),
    (2, 1, 2500, 1500, 120, 0x09),
]
GOLDEN_EVENT_OKAY = bytes.fromhex("A5 5A 7F 10 00 00 09 00 ED D8 4F 4B 41 59 32 36 43 46 0D 5C D3")
