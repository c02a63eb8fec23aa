"""Mutation fuzzer of the SPX host side: SelspotDecoder and the MCS-1 reply parser.

TARGETS.md: every decoder is fuzzed with >= 1 000 000 mutated inputs and only
the documented protocol errors may be raised. This is a seeded, bounded,
self-contained fuzzer (no atheris, no network), too long for ``make test``.

Inputs. Valid SPX streams are built from the spec by ``spotlab.simulators.wire``
(never by the driver's codec) for several layouts (1 x 1 to 4 x 128 LEDs x
cameras, fixed or any slot), with counter wraps, link losses, device drops,
restarts, duplicates, header flag bits, event frames, banners and ``AT\\r``
between frames. Each input is one such stream (from a corpus that is refreshed
as the run goes) mutated twice over:

* frame-aware, CRCs fixed afterwards so that the damage reaches the layers
  behind the checksums: any header or payload field set to a new value, the
  ``len`` field changed (header CRC fixed), frames resized with both CRCs
  correct (wrong length for the configuration), version 2, another frame type,
  frames turned into events (up to 4096 random bytes), duplicated, swapped,
  dropped;
* blind: bit flips, byte replacements, inserted garbage and tokens (sync words,
  headers alone, the banner, ``AT\\r``), deleted, repeated and swapped ranges,
  truncation of either end, splices of other streams (other layouts too); a
  few inputs are plain random bytes.

Each input is fed to three decoders of one layout: whole, in random chunks
(1 byte to more than a frame; stamps are the chunks' end offsets), and through
``feed_many`` with the same chunks; each then ``flush()``-es. Decoders live for
a run of inputs, with ``mark_discontinuity()`` between some of them (and, in a
few runs, ``flush()`` / ``mark_discontinuity()`` in the middle of an input).

Checked after every call (docs/drivers.md, the decoder's docstrings):

* nothing is raised (``feed`` never raises on bad bytes);
* every counter never decreases; ``stats.frames`` equals the frames returned;
  ``stats.bytes`` the bytes fed; ``bytes = accepted frame bytes + bytes_skipped
  + buffered``; the buffer stays below one frame (or one 4108-byte event
  frame) and is empty after ``flush()``; ``resyncs <= bytes_skipped`` and both
  zero or both not; ``device_dropped <= lost_frames``;
  ``gaps <= lost_frames + restarts``;
* blocks have the documented dtypes and shapes; x and y are integers in
  0..4094 or both NaN, NaN whenever flag bit 0 is clear; intensity an integer
  in 0..255; ``seq`` strictly increasing over the decoder's life; arrival
  stamps non-decreasing, each the stamp of a read of this input, none later
  than the read that returned it;
* event frames hold 1-4096 bytes found in the input; the banner flag is set only
  when the banner's bytes were fed;
* the three ways of feeding agree exactly (frames, values, counters, events;
  arrival stamps between the chunked two).

Replies: mutated reply lines (every ``ERRORxx`` code, ``WARNxx``, data replies,
the banner; blind damage, or damage inside the text with the CRC made valid
again) and every event payload the decoders found go to ``parse_reply`` (may
raise ``ProtocolError`` only), then ``Reply.raise_for_error`` (raises exactly the
documented ``DeviceError`` subclass for ``ERRORxx``, nothing otherwise),
``parse_version`` for ``VER:0`` replies (``ProtocolError`` only) and
``find_reply`` (never raises; returns a CRC-valid tail of the line or None).

Prints progress to stderr and one JSON line at the end. Exit code 1 when an
unexpected exception or an invariant violation happened; the first failing
input (with the inputs before it in the same decoder run) is saved as JSON and
can be replayed with ``--replay FILE``.

Usage: ``python benchmarks/fuzz_selspot.py [--inputs 1000000] [--seed 0] [--workers 2]
[--seconds S] [--failure-dir DIR]``
"""

from __future__ import annotations

import argparse
import binascii
import json
import logging
import multiprocessing
import os
import random
import sys
import tempfile
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from spotlab.core.errors import DeviceError, ProtocolError
from spotlab.core.frames import FrameBlock
from spotlab.drivers.mcs1.commands import (
    ERROR_MEANINGS,
    DeviceBandwidthError,
    DeviceConfigurationError,
    parse_reply,
)
from spotlab.drivers.mcs1.session import find_reply
from spotlab.drivers.selspot import SelspotDecoder
from spotlab.drivers.selspot.protocol import parse_version
from spotlab.simulators import wire

# (cameras, LEDs, slot_us the decoder requires; None accepts any) and their weights.
LAYOUTS = [(1, 1, 100), (1, 8, 100), (2, 3, 100), (2, 8, None), (3, 5, 250), (4, 32, 100)]
LAYOUTS += [(4, 128, 100)]
WEIGHTS = [2, 3, 4, 2, 2, 3, 1]
MAX_EVENT_FRAME = wire.MAX_PAYLOAD + wire.FRAME_OVERHEAD
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
PREFIXES = [None, "TIME", "SPX", "STAT", "LEDQ"]
TOKENS = [
    wire.SYNC,
    b"\xa5",
    b"\x5a",
    wire.BANNER,
    b"AT\r",
    wire.event_frame(wire.reply("OKAY")),
    wire.event_frame(wire.reply("ERROR80")),
    b"\r",
]


class Failure(Exception):
    """An invariant violation (not an exception the code under test raised)."""


def crc(data: bytes | bytearray) -> int:
    return binascii.crc_hqx(bytes(data), 0xFFFF)


# -- building valid streams ---------------------------------------------------------------
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


# -- mutations ------------------------------------------------------------------------------
def fix_crcs(b: bytearray, header: bool = True, payload: bool = True) -> None:
    if header:
        b[8:10] = crc(b[:8]).to_bytes(2, "little")
    if payload and len(b) >= 12:
        b[-2:] = crc(b[10:-2]).to_bytes(2, "little")


FIELDS = [(4, 2), (10, 4), (14, 4), (18, 2), (20, 2), (22, 2), (24, 1), (25, 1), (3, 1), (2, 1)]


def mutate_frame(rng: random.Random, f: bytes) -> list[bytes]:
    """One frame-aware mutation of a data frame; CRCs fixed where it keeps them valid."""
    b = bytearray(f)
    op = rng.randrange(10)
    if op <= 2:  # one field (or a record byte) to a new value, CRCs fixed
        if rng.random() < 0.7:
            off, size = rng.choice(FIELDS)
        else:
            off, size = rng.randrange(26, len(b) - 2), 1
        old = int.from_bytes(b[off : off + size], "little")
        value = rng.choice(
            [rng.getrandbits(8 * size), old + 1, old - 1, 0, (1 << (8 * size)) - 1, old + 2]
        )
        b[off : off + size] = (value % (1 << (8 * size))).to_bytes(size, "little")
        fix_crcs(b)
    elif op == 3:  # len field changed, header CRC fixed (payload CRC now wrong)
        plen = len(b) - 12
        new = rng.choice([plen + 1, plen - 1, 0, 1, 4096, 4097, 65535, rng.getrandbits(16)])
        b[6:8] = (new % 65536).to_bytes(2, "little")
        fix_crcs(b, payload=False)
    elif op == 4:  # CRC-correct frame of the wrong length
        d = rng.choice([1, 5, 10, rng.randint(1, 40)])
        if rng.random() < 0.5 and len(b) - 12 - d >= 1:
            b = b[: -2 - d] + b[-2:]
        else:
            b = b[:-2] + bytearray(rng.randbytes(d)) + b[-2:]
        b[6:8] = (len(b) - 12).to_bytes(2, "little")
        fix_crcs(b)
    elif op == 5:  # version 2, or another frame type (header CRC fixed)
        if rng.random() < 0.5:
            b[3] = (rng.choice([0, 2, 15]) << 4) | (b[3] & 0x0F)
        else:
            b[2] = rng.choice([0x02, 0x03, 0x04, 0x00, 0xFF])
        fix_crcs(b, payload=False)
    elif op == 6:  # turned into an event frame: its payload, a reply, or random bytes
        choice = rng.random()
        if choice < 0.4:
            payload = bytes(b[10:-2])
        elif choice < 0.7:
            payload = wire.reply(rng.choice(REPLY_TEXTS))
        else:
            payload = rng.randbytes(rng.choice([1, 2, 9, 300, 4096, rng.randint(1, 4096)]))
        return [wire.event_frame(payload)]
    elif op == 7:  # duplicated (same seq), or sent twice around other bytes
        return [f, f] if rng.random() < 0.7 else [f, rng.choice(TOKENS), f]
    elif op == 8:  # dropped
        return []
    else:  # an event header claiming too much, or nothing
        head = bytearray(wire.SYNC + bytes([0x7F, 0x10, 0, 0]))
        head += rng.choice([0, 4097, 65535]).to_bytes(2, "little") + b"\0\0"
        fix_crcs(head, payload=False)
        return [bytes(head), f]
    return [bytes(b)]


def mutate_blind(rng: random.Random, b: bytearray, corpus: list[Stream]) -> bytearray:
    if not b:
        return bytearray(rng.randbytes(rng.randint(0, 64)))
    n = len(b)
    i = rng.randrange(n)
    op = rng.randrange(11)
    if op == 0:
        for _ in range(rng.randint(1, 4)):
            b[rng.randrange(n)] ^= 1 << rng.randrange(8)
    elif op == 1:
        for _ in range(rng.randint(1, 3)):
            b[rng.randrange(n)] = rng.choice([0, 0xFF, 0xA5, 0x5A, 0x0D, rng.getrandbits(8)])
    elif op == 2:
        b[i:i] = rng.randbytes(rng.choice([1, 2, 3, 10, rng.randint(1, 64)]))
    elif op == 3:
        token = rng.choice(TOKENS) if rng.random() < 0.8 else b"\xa5\x5a" + rng.randbytes(8)
        b[i:i] = token
    elif op == 4:
        del b[i : i + rng.choice([1, 2, 5, 12, rng.randint(1, 100)])]
    elif op == 5:
        b[i:i] = b[i : i + rng.randint(1, 3000)]
    elif op == 6:
        del b[i:]
    elif op == 7:
        del b[:i]
    elif op == 8:  # splice a piece of another stream (maybe another layout)
        other = rng.choice(corpus).joined()
        j = rng.randrange(len(other))
        part = other[j : j + rng.randint(1, 4000)]
        if rng.random() < 0.5:
            b[i:i] = part
        else:
            b[i:] = part
    elif op == 9:  # swap two ranges
        j = rng.randrange(n)
        lo, hi = min(i, j), max(i, j)
        size = rng.randint(1, 200)
        if lo + size <= hi:
            b[lo : lo + size], b[hi : hi + size] = b[hi : hi + size], b[lo : lo + size]
    else:
        b[i : i + 1] = b"\xa5\x5a"
    return b


def make_input(rng: random.Random, stream: Stream, all_streams: list[Stream]) -> bytes:
    r = rng.random()
    if r < 0.02:
        return rng.randbytes(rng.randint(0, 3000))
    if r < 0.03:
        junk = bytearray(rng.randbytes(rng.randint(0, 2000)))
        for _ in range(rng.randint(1, 20)):
            k = rng.randrange(len(junk) + 1)
            junk[k:k] = wire.SYNC
        return bytes(junk)
    pieces = list(stream.pieces)
    if r < 0.06:
        return b"".join(pieces)  # valid as built
    if rng.random() < 0.6:
        frames = [k for k, f in enumerate(stream.is_frame) if f]
        for _ in range(rng.randint(1, 3)):
            if not frames:
                break
            k = rng.choice(frames)
            if rng.random() < 0.9:
                pieces[k] = b"".join(mutate_frame(rng, pieces[k]))
                frames.remove(k)  # no longer a data frame of the layout
            else:  # swap with another frame
                j = rng.choice(frames)
                pieces[k], pieces[j] = pieces[j], pieces[k]
    data = bytearray(b"".join(pieces))
    blind = rng.choice([0, 1, 1, 2, 3, 6]) if rng.random() < 0.8 else 0
    for _ in range(blind):
        data = mutate_blind(rng, data, all_streams)
    return bytes(data)


def make_cuts(rng: random.Random, n: int, frame_len: int) -> list[int]:
    """Chunk end offsets (the last one is ``n``)."""
    if n == 0:
        return [0] if rng.random() < 0.5 else []
    mode = rng.random()
    cuts: list[int] = []
    if mode < 0.04 and n <= 600:
        return list(range(1, n + 1))
    if mode < 0.45:
        pos = 0
        top = rng.choice([4, 32, 128, 128, 600, 600])
        while pos < n:
            pos = min(n, pos + rng.randint(1, top))
            cuts.append(pos)
        return cuts
    if mode < 0.7:
        pos = 0
        while pos < n:
            pos = min(n, pos + max(1, frame_len + rng.randint(-12, 12)))
            cuts.append(pos)
        return cuts
    cuts = sorted(rng.randint(0, n) for _ in range(rng.randint(0, 12)))
    return [*cuts, n]


# -- checking -------------------------------------------------------------------------------
COUNTERS = (
    "frames",
    "lost_frames",
    "device_dropped",
    "crc_errors",
    "resyncs",
    "bytes_skipped",
    "duplicates",
    "gaps",
    "reconnects",
    "bytes",
)


class Checked:
    """A decoder and what must hold of it after every call."""

    def __init__(self, cams: int, leds: int, slot: int | None) -> None:
        self.dec = SelspotDecoder(cams, leds, slot)
        self.shape = (leds, cams)
        self.limit = max(self.dec.frame_bytes, MAX_EVENT_FRAME)
        self.frames_out = 0
        self.bytes_in = 0
        self.last_seq = -(1 << 62)
        self.last_arrival = -(1 << 62)
        self.counters = self.snapshot()
        self.blocks: list[FrameBlock] = []
        self.events: list[bytes] = []
        self.tail = b""

    def snapshot(self) -> tuple[int, ...]:
        d, s = self.dec, self.dec.stats
        return (
            *(getattr(s, name) for name in COUNTERS),
            d.config_mismatches,
            d.restarts,
            d.frame_bytes_accepted,
        )

    def call(self, what: str, *args: Any) -> FrameBlock | None:
        try:
            return getattr(self.dec, what)(*args)
        except Exception as exc:
            raise UnexpectedError(f"{what} raised {type(exc).__name__}: {exc}") from exc

    def feed(self, data: bytes, stamp: int, stamps: set[int]) -> None:
        self.bytes_in += len(data)
        block = self.call("feed", data, stamp)
        self.after(block, stamp, stamps, flushed=False)

    def feed_many(self, chunks: list[tuple[bytes, int]], stamps: set[int]) -> None:
        self.bytes_in += sum(len(c) for c, _ in chunks)
        block = self.call("feed_many", chunks)
        self.after(block, chunks[-1][1] if chunks else 0, stamps, flushed=False)

    def flush(self, stamp: int, stamps: set[int]) -> None:
        block = self.call("flush")
        self.after(block, stamp, stamps, flushed=True)

    def mark(self) -> None:
        self.call("mark_discontinuity")
        self.after(None, 0, set(), flushed=True)

    def after(self, block: Any, stamp: int, stamps: set[int], flushed: bool) -> None:
        dec, s = self.dec, self.dec.stats
        if block is not None:
            self.check_block(block, stamp, stamps)
        now = self.snapshot()
        if any(b < a for a, b in zip(self.counters, now, strict=True)):
            raise Failure(f"a counter decreased: {self.counters} -> {now}")
        self.counters = now
        if s.frames != self.frames_out:
            raise Failure(f"stats.frames {s.frames} != frames returned {self.frames_out}")
        if s.bytes != self.bytes_in:
            raise Failure(f"stats.bytes {s.bytes} != bytes fed {self.bytes_in}")
        if s.bytes != dec.frame_bytes_accepted + s.bytes_skipped + dec.buffered:
            raise Failure(
                f"bytes {s.bytes} != accepted {dec.frame_bytes_accepted} + skipped "
                f"{s.bytes_skipped} + buffered {dec.buffered}"
            )
        if dec.buffered >= self.limit or (flushed and dec.buffered):
            raise Failure(f"{dec.buffered} bytes buffered (flushed: {flushed})")
        if s.resyncs > s.bytes_skipped or (s.resyncs > 0) != (s.bytes_skipped > 0):
            raise Failure(f"resyncs {s.resyncs} vs bytes_skipped {s.bytes_skipped}")
        if s.device_dropped > s.lost_frames:
            raise Failure(f"device_dropped {s.device_dropped} > lost_frames {s.lost_frames}")
        if s.gaps > s.lost_frames + dec.restarts:
            raise Failure(f"gaps {s.gaps} > lost {s.lost_frames} + restarts {dec.restarts}")

    def check_block(self, block: Any, stamp: int, stamps: set[int]) -> None:
        if not isinstance(block, FrameBlock):
            raise Failure(f"returned {type(block).__name__}, not a FrameBlock")
        k = len(block)
        n_leds, n_cams = self.shape
        for name, dtype, shape in (
            ("seq", np.int64, (k,)),
            ("ticks", np.int64, (k,)),
            ("arrival_ns", np.int64, (k,)),
            ("status", np.uint16, (k,)),
            ("data", np.float64, (k, n_leds, n_cams, 3)),
            ("flags", np.uint8, (k, n_leds, n_cams)),
        ):
            arr = getattr(block, name)
            if arr.dtype != dtype or arr.shape != shape:
                raise Failure(f"block.{name} is {arr.dtype} {arr.shape}, not {dtype} {shape}")
        if not k:
            return
        self.frames_out += k
        self.blocks.append(block)
        seq = block.seq
        if seq[0] <= self.last_seq or (k > 1 and not (np.diff(seq) > 0).all()):
            raise Failure(f"seq not strictly increasing: {self.last_seq} then {seq.tolist()}")
        self.last_seq = int(seq[-1])
        arrival = block.arrival_ns
        if arrival[0] < self.last_arrival or (k > 1 and (np.diff(arrival) < 0).any()):
            raise Failure(f"arrival stamps go back: {self.last_arrival} then {arrival.tolist()}")
        if int(arrival[-1]) > stamp or not set(arrival.tolist()) <= stamps:
            raise Failure(f"arrival stamps {arrival.tolist()} not among this input's reads")
        self.last_arrival = int(arrival[-1])
        xy = block.data[..., :2]
        nan = np.isnan(xy)
        if (nan[..., 0] != nan[..., 1]).any():
            raise Failure("x NaN where y is not, or the reverse")
        valid = xy[~nan]
        if ((valid < 0) | (valid > 4094) | (valid != np.floor(valid))).any():
            raise Failure(f"coordinates outside 0..4094: {valid[(valid < 0) | (valid > 4094)]}")
        if ((block.flags & 1) == 0)[~nan[..., 0]].any():
            raise Failure("a coordinate given although flag bit 0 is clear")
        inten = block.data[..., 2]
        if not ((inten >= 0) & (inten <= 255) & (inten == np.floor(inten))).all():
            raise Failure("intensity not an integer in 0..255")

    def end_input(self, data: bytes) -> None:
        events = self.dec.take_events()
        for ev in events:
            if not 1 <= len(ev.payload) <= wire.MAX_PAYLOAD or ev.payload not in data:
                raise Failure(f"event payload {ev.payload[:40]!r}... not in the input")
            self.events.append(ev.payload)
        if self.dec.banner_seen:
            if wire.BANNER not in self.tail + data:
                raise Failure("banner_seen set without the banner's bytes")
            self.dec.banner_seen = False
        self.tail = (self.tail + data)[-(len(wire.BANNER) - 1) :]

    def result(self) -> tuple[Any, ...]:
        """Everything the three ways of feeding must agree on (arrival stamps apart)."""
        frames: tuple[Any, ...] = ()
        if self.blocks:
            b = FrameBlock.concat(self.blocks)
            frames = (b.seq, b.ticks, b.status, b.flags, b.data)
        return frames, self.snapshot(), tuple(self.events)

    def arrivals(self) -> Any:
        return np.concatenate([b.arrival_ns for b in self.blocks]) if self.blocks else None

    def reset_outputs(self) -> None:
        self.blocks.clear()
        self.events.clear()


class UnexpectedError(Exception):
    """The code under test raised something it does not document."""


def same(a: tuple[Any, ...], b: tuple[Any, ...]) -> bool:
    (fa, ca, ea), (fb, cb, eb) = a, b
    if ca != cb or ea != eb or len(fa) != len(fb):
        return False
    return all(np.array_equal(x, y, equal_nan=True) for x, y in zip(fa, fb, strict=True))


# -- one run of inputs through three decoders ------------------------------------------------
@dataclass
class Step:
    data: bytes
    cuts: list[int]
    mark_before: bool = False
    many: bool = True
    mid: list[tuple[int, str]] = field(default_factory=list)  # (chunk index, flush|mark)

    def to_json(self) -> dict[str, Any]:
        return {
            "data": self.data.hex(),
            "cuts": self.cuts,
            "mark_before": self.mark_before,
            "many": self.many,
            "mid": self.mid,
        }

    @classmethod
    def from_json(cls, d: dict[str, Any]) -> Step:
        return cls(
            bytes.fromhex(d["data"]),
            d["cuts"],
            d["mark_before"],
            d["many"],
            [(int(i), str(w)) for i, w in d["mid"]],
        )


class DecoderRun:
    """Three decoders of one layout fed the same inputs three ways."""

    def __init__(self, layout: tuple[int, int, int | None]) -> None:
        self.layout = layout
        self.whole = Checked(*layout)
        self.chunked = Checked(*layout)
        self.many = Checked(*layout)
        self.offset = 0  # stamps: stream offset of each read's end, over the run
        self.diverged = False  # mid-input flush/mark given to the chunked decoder only
        self.steps: list[Step] = []

    def step(self, st: Step) -> list[bytes]:
        """Feed one input; return the event payloads found (for the reply parser)."""
        self.steps.append(st)
        data, base = st.data, self.offset
        self.offset += len(data) + 1
        decoders = (self.whole, self.chunked, self.many)
        if st.mark_before:
            for c in decoders:
                c.mark()
        for c in decoders:
            c.reset_outputs()
        chunks, pos = [], 0
        for end in st.cuts:
            chunks.append((data[pos:end], base + end))
            pos = end
        stamps = {t for chunk, t in chunks if chunk}
        end_stamp = base + len(data)
        self.whole.feed(data, end_stamp, {end_stamp})
        self.whole.flush(end_stamp, {end_stamp})
        mid = dict(st.mid)
        for k, (chunk, t) in enumerate(chunks):
            self.chunked.feed(chunk, t, stamps)
            if k in mid:
                self.diverged = True
                if mid[k] == "flush":
                    self.chunked.flush(t, stamps)
                else:
                    self.chunked.mark()
        self.chunked.flush(end_stamp, stamps)
        if st.many:
            self.many.feed_many(chunks, stamps)
            self.many.flush(end_stamp, stamps)
        else:
            for chunk, t in chunks:
                self.many.feed(chunk, t, stamps)
            self.many.flush(end_stamp, stamps)
        for c in decoders:
            c.end_input(data)
        if not self.diverged:
            reference = self.chunked.result()
            if not same(self.whole.result(), reference):
                raise Failure("whole input and chunks decode differently")
            if not same(self.many.result(), reference):
                raise Failure("feed_many and feed decode differently")
            a, b = self.chunked.arrivals(), self.many.arrivals()
            if (a is None) != (b is None) or (a is not None and not np.array_equal(a, b)):
                raise Failure("feed_many and feed give different arrival stamps")
        return list(self.chunked.events)


# -- replies --------------------------------------------------------------------------------
def make_reply(rng: random.Random) -> tuple[bytes, str | None]:
    text = rng.choice(REPLY_TEXTS).encode()
    prefix = rng.choice(PREFIXES)
    r = rng.random()
    if r < 0.05:
        return wire.reply(text.decode()), prefix
    if r < 0.5:  # damage inside the text, CRC made valid again
        body = bytearray(text)
        for _ in range(rng.randint(1, 3)):
            body = mutate_text(rng, body)
        return bytes(body) + f"{crc(body):04X}\r".encode(), prefix
    line = bytearray(wire.reply(text.decode()))
    for _ in range(rng.randint(1, 3)):
        line = mutate_text(rng, line)
    return bytes(line), prefix


def mutate_text(rng: random.Random, b: bytearray) -> bytearray:
    if not b:
        return bytearray(rng.randbytes(rng.randint(0, 8)))
    i = rng.randrange(len(b))
    op = rng.randrange(6)
    if op == 0:
        b[i] ^= 1 << rng.randrange(8)
    elif op == 1:
        b[i] = rng.choice([0x20, 0x0D, 0x00, 0x7F, 0xFF, ord("a"), ord("F"), rng.getrandbits(8)])
    elif op == 2:
        b[i:i] = rng.choice([b" ", b"\r", b"AT", b"0", rng.randbytes(rng.randint(1, 6))])
    elif op == 3:
        del b[i : i + rng.randint(1, 4)]
    elif op == 4:
        del b[i:]
    else:
        b[i:i] = b[i : i + rng.randint(1, 20)]
    return b


def check_reply(line: bytes, prefix: str | None) -> None:
    """parse_reply and what follows it: only the documented errors, right results."""
    try:
        tail = find_reply(line)
    except Exception as exc:
        raise UnexpectedError(f"find_reply raised {type(exc).__name__}: {exc}") from exc
    if tail is not None and (not line.endswith(tail) or not tail.endswith(b"\r")):
        raise Failure(f"find_reply gave {tail!r}, not a reply at the end of {line!r}")
    try:
        reply = parse_reply(line, prefix)
    except ProtocolError:
        return
    except Exception as exc:
        raise UnexpectedError(f"parse_reply raised {type(exc).__name__}: {exc}") from exc
    body, crc_text = line[:-5], line[-5:-1]
    ok_crc = line.endswith(b"\r") and crc_text == f"{crc(body):04X}".encode()
    if not ok_crc or reply.raw != line or reply.text.encode("ascii") != body or tail != line:
        raise Failure(f"parse_reply accepted {line!r} as {reply!r}")
    kind, text, code = reply.kind, reply.text, reply.code
    if kind == "okay":
        good = text == "OKAY" and code is None
    elif kind in ("error", "warn"):
        word = "ERROR" if kind == "error" else "WARN"
        good = code is not None and text == f"{word}{code:02X}"
    elif kind == "data":
        good = prefix is not None and (text == prefix or text.startswith(prefix + " "))
    else:
        good = False
    if not good:
        raise Failure(f"parse_reply({line!r}, {prefix!r}) gave {reply!r}")
    try:
        same_reply = reply.raise_for_error("X:")
    except DeviceError as exc:
        if kind != "error" or exc.code != code:
            raise Failure(f"raise_for_error raised {exc!r} for {reply!r}") from exc
        expected: type[DeviceError] = DeviceError
        if code == 0x80:
            expected = DeviceBandwidthError
        elif code in (0x23, 0x81, 0x82):
            expected = DeviceConfigurationError
        if type(exc) is not expected:
            raise Failure(
                f"{reply.text} raised {type(exc).__name__}, not {expected.__name__}"
            ) from exc
    except Exception as exc:
        raise UnexpectedError(f"raise_for_error raised {type(exc).__name__}: {exc}") from exc
    else:
        if kind == "error" or same_reply is not reply:
            raise Failure(f"raise_for_error did not raise for {reply!r}")
    if kind == "data" and prefix == "SPX":
        try:
            parse_version(text)
        except ProtocolError:
            pass
        except Exception as exc:
            raise UnexpectedError(f"parse_version raised {type(exc).__name__}: {exc}") from exc


# -- workers ----------------------------------------------------------------------------------
@dataclass
class Tally:
    inputs: int = 0
    reply_inputs: int = 0
    bytes: int = 0
    unexpected_exceptions: int = 0
    invariant_violations: int = 0
    failures: list[str] = field(default_factory=list)
    failure_file: str | None = None
    totals: dict[str, int] = field(default_factory=dict)

    def add_totals(self, checked: Checked) -> None:
        s = checked.dec.stats
        for name in ("frames", "lost_frames", "crc_errors", "resyncs", "duplicates", "gaps"):
            self.totals[name] = self.totals.get(name, 0) + getattr(s, name)
        self.totals["restarts"] = self.totals.get("restarts", 0) + checked.dec.restarts
        mism = self.totals.get("config_mismatches", 0) + checked.dec.config_mismatches
        self.totals["config_mismatches"] = mism


def record_failure(
    tally: Tally, exc: Exception, record: dict[str, Any], failure_path: Path
) -> None:
    if isinstance(exc, UnexpectedError):
        tally.unexpected_exceptions += 1
        cause = exc.__cause__
        detail = "".join(traceback.format_exception(cause)) if cause else str(exc)
    else:
        tally.invariant_violations += 1
        detail = "".join(traceback.format_exception(exc))
    if len(tally.failures) < 5:
        tally.failures.append(str(exc))
    if tally.failure_file is None:
        record = {**record, "message": str(exc), "traceback": detail}
        failure_path.write_text(json.dumps(record, indent=1))
        tally.failure_file = str(failure_path)


def worker(
    seed: int, n_inputs: int, seconds: float | None, failure_dir: str, wid: int
) -> dict[str, Any]:
    logging.disable(logging.CRITICAL)  # decoders log config mismatches, replies log WARNxx
    rng = random.Random(seed)
    corpus = {lay: [build_stream(rng, *lay) for _ in range(CORPUS_PER_LAYOUT)] for lay in LAYOUTS}
    all_streams = [s for streams in corpus.values() for s in streams]
    tally = Tally()
    failure_path = Path(failure_dir) / f"fuzz_selspot-failure-seed{seed}.json"
    t0 = time.monotonic()
    deadline = None if seconds is None else t0 + seconds
    next_report = t0 + 10.0
    run: DecoderRun | None = None
    left = 0
    while tally.inputs < n_inputs:
        now = time.monotonic()
        if deadline is not None and now >= deadline:
            break
        if now >= next_report:
            next_report = now + 10.0
            print(
                f"[worker {wid}] {tally.inputs}/{n_inputs} inputs, "
                f"{tally.inputs / (now - t0):.0f}/s, unexpected {tally.unexpected_exceptions}, "
                f"violations {tally.invariant_violations}",
                file=sys.stderr,
                flush=True,
            )
        if run is None or left == 0:
            if run is not None:
                for c in (run.whole, run.chunked, run.many):
                    tally.add_totals(c)
            layout = rng.choices(LAYOUTS, WEIGHTS)[0]
            run = DecoderRun(layout)
            left = rng.randint(1, 64)
        left -= 1
        layout = run.layout
        streams = corpus[layout]
        if rng.random() < 0.02:  # refresh the corpus as the run goes
            streams[rng.randrange(len(streams))] = build_stream(rng, *layout)
            all_streams = [s for ss in corpus.values() for s in ss]
        data = make_input(rng, rng.choice(streams), all_streams)
        frame_len = run.whole.dec.frame_bytes
        cuts = make_cuts(rng, len(data), frame_len)
        st = Step(data, cuts, mark_before=rng.random() < 0.3, many=rng.random() < 0.7)
        if rng.random() < 0.05 and len(cuts) > 1:
            st.mid = [(rng.randrange(len(cuts)), rng.choice(["flush", "mark"]))]
        tally.inputs += 1
        tally.bytes += len(data)
        try:
            events = run.step(st)
        except (Failure, UnexpectedError) as exc:
            record: dict[str, Any] = {"kind": "decoder", "layout": list(layout)}
            record["steps"] = [s.to_json() for s in run.steps]
            record_failure(tally, exc, record, failure_path)
            run, left = None, 0
            continue
        line, prefix = make_reply(rng)
        for payload, pre in [(line, prefix), *((e, None) for e in events[:4])]:
            tally.reply_inputs += 1
            try:
                check_reply(payload, pre)
            except (Failure, UnexpectedError) as exc:
                record = {"kind": "reply", "line": payload.hex(), "prefix": pre}
                record_failure(tally, exc, record, failure_path)
    if run is not None:
        for c in (run.whole, run.chunked, run.many):
            tally.add_totals(c)
    return {
        "tally": tally.__dict__,
        "seconds": time.monotonic() - t0,
    }


def replay(path: Path) -> int:
    logging.disable(logging.CRITICAL)
    record = json.loads(path.read_text())
    try:
        if record["kind"] == "reply":
            check_reply(bytes.fromhex(record["line"]), record["prefix"])
        else:
            cams, leds, slot = record["layout"]
            run = DecoderRun((cams, leds, slot))
            for d in record["steps"]:
                run.step(Step.from_json(d))
    except (Failure, UnexpectedError) as exc:
        cause = exc.__cause__ or exc
        traceback.print_exception(cause)
        return 1
    print("replayed without failure", file=sys.stderr)
    return 0


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--inputs", type=int, default=1_000_000, help="mutated SPX streams")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--seconds", type=float, help="stop after this long (a cap)")
    parser.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1))
    parser.add_argument(
        "--failure-dir", default=tempfile.gettempdir(), help="where the first failure is saved"
    )
    parser.add_argument("--replay", type=Path, help="re-run a saved failure and show it")
    args = parser.parse_args(argv)
    if args.replay:
        return replay(args.replay)
    workers = max(1, args.workers)
    share = [args.inputs // workers + (k < args.inputs % workers) for k in range(workers)]
    seeds = [args.seed * 1000 + k for k in range(workers)]
    t0 = time.monotonic()
    jobs = [(seeds[k], share[k], args.seconds, args.failure_dir, k) for k in range(workers)]
    if workers == 1:
        results = [worker(*jobs[0])]
    else:
        with multiprocessing.get_context("spawn").Pool(workers) as pool:
            results = pool.starmap(worker, jobs)
    elapsed = time.monotonic() - t0
    tallies = [r["tally"] for r in results]
    totals: dict[str, int] = {}
    for t in tallies:
        for k, v in t["totals"].items():
            totals[k] = totals.get(k, 0) + v
    inputs = sum(t["inputs"] for t in tallies)
    summary = {
        "benchmark": "fuzz_selspot",
        "inputs": inputs,
        "inputs_requested": args.inputs,
        "reply_inputs": sum(t["reply_inputs"] for t in tallies),
        "bytes": sum(t["bytes"] for t in tallies),
        "unexpected_exceptions": sum(t["unexpected_exceptions"] for t in tallies),
        "invariant_violations": sum(t["invariant_violations"] for t in tallies),
        "seconds": round(elapsed, 1),
        "inputs_per_s": round(inputs / elapsed) if elapsed > 0 else None,
        "workers": workers,
        "seeds": seeds,
        "decoded": totals,
    }
    failures = [f for t in tallies for f in t["failures"]]
    if failures:
        summary["failures"] = failures[:5]
        summary["failure_files"] = [t["failure_file"] for t in tallies if t["failure_file"]]
    print(json.dumps(summary), flush=True)
    bad = summary["unexpected_exceptions"] or summary["invariant_violations"]
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
