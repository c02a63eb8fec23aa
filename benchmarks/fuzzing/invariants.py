"""What must hold of a decoder after every call (docs/drivers.md, the decoder's docstrings).

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
  when the banner's bytes were fed.

A broken rule raises :class:`Failure`; an exception the code under test does
not document is re-raised as :class:`UnexpectedError` (see :func:`call`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar

import numpy as np

from spotlab.core.frames import FrameBlock
from spotlab.drivers.selspot import SelspotDecoder
from spotlab.simulators import wire

T = TypeVar("T")
MAX_EVENT_FRAME = wire.MAX_PAYLOAD + wire.FRAME_OVERHEAD
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


class Failure(Exception):
    """An invariant violation (not an exception the code under test raised)."""


class UnexpectedError(Exception):
    """The code under test raised something it does not document."""


def call(
    what: str,
    fn: Callable[..., T],
    *args: Any,
    allowed: tuple[type[Exception], ...] = (),
) -> T:
    """``fn(*args)``; any exception but the ``allowed`` ones becomes :class:`UnexpectedError`."""
    try:
        return fn(*args)
    except allowed:
        raise
    except Exception as exc:
        raise UnexpectedError(f"{what} raised {type(exc).__name__}: {exc}") from exc


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

    def call(self, what: str, *args: Any) -> Any:
        return call(what, getattr(self.dec, what), *args)

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


def same(a: tuple[Any, ...], b: tuple[Any, ...]) -> bool:
    (fa, ca, ea), (fb, cb, eb) = a, b
    if ca != cb or ea != eb or len(fa) != len(fb):
        return False
    return all(np.array_equal(x, y, equal_nan=True) for x, y in zip(fa, fb, strict=True))
