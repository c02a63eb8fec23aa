"""Valid SPX streams, built from the spec by ``spotlab.simulators.wire``.

Never by the driver's codec. Several layouts (1 x 1 to 4 x 128 LEDs x cameras,
fixed or any slot), with counter wraps, link losses, device drops, restarts,
duplicates, header flag bits, event frames, banners and ``AT\\r`` between
frames. A :class:`Corpus` holds some streams of every layout and is refreshed
as the run goes.
"""

from __future__ import annotations

import binascii
import random
from dataclasses import dataclass

import numpy as np

from spotlab.drivers.mcs1.commands import ERROR_MEANINGS
from spotlab.simulators import wire

Layout = tuple[int, int, int | None]

# (cameras, LEDs, slot_us the decoder requires; None accepts any) and their weights.
LAYOUTS: list[Layout] = [(1, 1, 100), (1, 8, 100), (2, 3, 100), (2, 8, None), (3, 5, 250)]
LAYOUTS += [(4, 32, 100), (4, 128, 100)]
WEIGHTS = [2, 3, 4, 2, 2, 3, 1]
CORPUS_PER_LAYOUT = 24
REPLY_TEXTS = [
    "OKAY",
    *(f"ERROR{code:02X}" for code in ERROR_MEANINGS),
    "ERRORFF",
    "WARN05",
    "WARN83",
    "TIME 0001E240 0001E2A4",
    "SPX 1.0 SIM00042 4 128",
    "SPX 1.0 SIM00042 x 128",
    "STAT 0004",
    "LEDQ 00800580",
    "RESET",
]


def crc(data: bytes | bytearray) -> int:
    """The MCS-1 CRC-16 (CCITT, initial value 0xFFFF)."""
    return binascii.crc_hqx(bytes(data), 0xFFFF)


@dataclass
class Stream:
    """A valid SPX stream as pieces; ``is_frame`` marks the data frames."""

    pieces: list[bytes]
    is_frame: list[bool]

    def joined(self) -> bytes:
        return b"".join(self.pieces)


def build_stream(rng: random.Random, cams: int, leds: int, slot: int | None) -> Stream:
    nrng = np.random.default_rng(rng.getrandbits(63))
    n_frames = rng.randint(1, 5 if cams * leds > 100 else 24)
    seq = rng.choice([0, 0, rng.randrange(65536), 65530 + rng.randrange(6)])
    frame_no = seq if rng.random() < 0.7 else rng.choice([rng.getrandbits(32), 0xFFFFFFF0])
    tick = rng.getrandbits(32)
    period = rng.choice([5000, 14286, 1000, 0x7FFFFFFF, 0])
    slot_us = slot if slot is not None else rng.choice([50, 100, 1000])
    pieces: list[bytes] = []
    is_frame: list[bool] = []
    for _ in range(n_frames):
        r = rng.random()
        if r < 0.06:
            pieces.append(wire.event_frame(wire.reply(rng.choice(REPLY_TEXTS))))
        elif r < 0.08:
            pieces.append(wire.BANNER)
        elif r < 0.10:
            pieces.append(b"AT\r")
        elif r < 0.12:
            pieces.append(rng.randbytes(rng.randint(1, 20)))
        if len(pieces) > len(is_frame):
            is_frame.append(False)
        status = 0
        r = rng.random()
        if r < 0.05:  # link loss
            seq += rng.randint(1, 5)
            frame_no += rng.randint(1, 5)
        elif r < 0.09:  # device drop (FIFO overflow)
            frame_no += rng.randint(1, 5)
            status |= wire.STATUS_FIFO_OVERFLOW
        elif r < 0.11:  # device restarted its stream
            seq = frame_no = 0
        if rng.random() < 0.1:
            status |= rng.getrandbits(16)
        n = leds * cams
        x = nrng.integers(0, 4095, n)
        y = nrng.integers(0, 4095, n)
        hidden = nrng.random(n) < 0.15
        x[hidden] = wire.INVALID
        y[hidden] = wire.INVALID
        flags = np.where(hidden, wire.FLAG_LOW_SIGNAL, wire.FLAG_VALID)
        if rng.random() < 0.2:
            flags = nrng.integers(0, 256, n)
        payload = wire.spx_payload(
            frame_no,
            tick,
            status,
            slot_us,
            x.reshape(leds, cams),
            y.reshape(leds, cams),
            nrng.integers(0, 256, n).reshape(leds, cams),
            flags.reshape(leds, cams),
        )
        header_flags = 0x10 | (rng.getrandbits(3) if rng.random() < 0.1 else 0)
        frame = wire.frame(wire.FRAME_SPX, seq, payload, header_flags)
        pieces.append(frame)
        is_frame.append(True)
        if rng.random() < 0.03:  # a duplicate on the link
            pieces.append(frame)
            is_frame.append(True)
        seq += 1
        frame_no += 1
        tick = (tick + period) & 0xFFFFFFFF
    return Stream(pieces, is_frame)


class Corpus:
    """:data:`CORPUS_PER_LAYOUT` streams of every layout, refreshed one at a time."""

    def __init__(self, rng: random.Random) -> None:
        self.by_layout = {
            lay: [build_stream(rng, *lay) for _ in range(CORPUS_PER_LAYOUT)] for lay in LAYOUTS
        }
        self.all = self._all()

    def _all(self) -> list[Stream]:
        return [s for streams in self.by_layout.values() for s in streams]

    def refresh(self, rng: random.Random, layout: Layout) -> None:
        """Replace one stream of ``layout`` by a new one."""
        streams = self.by_layout[layout]
        streams[rng.randrange(len(streams))] = build_stream(rng, *layout)
        self.all = self._all()
