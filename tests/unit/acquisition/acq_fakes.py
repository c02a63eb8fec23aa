"""In-test devices, sinks and a toy wire format for the acquisition unit tests.

Toy frame on the wire (13 bytes): ``b"TOY!"``, seq u32, ticks u32, checksum u8
(sum of the 8 bytes of seq and ticks, modulo 256). One marker, one sensor,
one value: the sequence number as a float.
"""

from __future__ import annotations

import struct
import threading
import time
from typing import Any

import numpy as np

from spotlab.core.errors import ProtocolError
from spotlab.core.frames import FrameBlock
from spotlab.core.stats import LinkStats
from spotlab.core.streams import StreamSpec
from spotlab.core.wire import WireTap

MAGIC = b"TOY!"
FRAME = struct.Struct("<4sII")
FRAME_SIZE = FRAME.size + 1
TICK_HZ = 1000.0


def encode_frames(
    seqs: list[int] | range, ticks_per_frame: int = 5, corrupt: int | None = None
) -> bytes:
    """Wire bytes of toy frames; ``corrupt``: seq whose checksum is made wrong."""
    out = bytearray()
    for s in seqs:
        body = FRAME.pack(MAGIC, s, s * ticks_per_frame)
        check = sum(body[4:]) & 0xFF
        if s == corrupt:
            check ^= 0xFF
        out += body + bytes([check])
    return bytes(out)


def make_block(seq: np.ndarray, ticks: np.ndarray, arrival_ns: int | np.ndarray) -> FrameBlock:
    n = len(seq)
    return FrameBlock(
        seq=np.asarray(seq, np.int64),
        ticks=np.asarray(ticks, np.int64),
        arrival_ns=np.broadcast_to(np.asarray(arrival_ns, np.int64), (n,)).copy(),
        data=np.asarray(seq, np.float64).reshape(n, 1, 1, 1),
        flags=np.ones((n, 1, 1), np.uint8),
        status=np.zeros(n, np.uint16),
    )


class ToyDecoder:
    """The toy wire format's decoder: counts losses, checksum errors, resyncs, duplicates."""

    def __init__(self, metadata: dict[str, Any]) -> None:
        if metadata.get("family") != "toy":
            raise ProtocolError(f"not a toy stream: {metadata.get('family')!r}")
        self.stats = LinkStats()
        self._buf = bytearray()
        self._last: int | None = None
        self.discontinuities = 0

    def feed(self, data: bytes, arrival_ns: int) -> FrameBlock:
        self.stats.bytes += len(data)
        buf = self._buf
        buf += data
        seqs: list[int] = []
        ticks: list[int] = []
        pos = 0
        while len(buf) - pos >= FRAME_SIZE:
            if not buf.startswith(MAGIC, pos):
                nxt = buf.find(MAGIC, pos + 1)
                nxt = len(buf) - 3 if nxt < 0 else nxt
                self.stats.resyncs += 1
                self.stats.bytes_skipped += nxt - pos
                pos = nxt
                continue
            _, seq, tick = FRAME.unpack_from(buf, pos)
            if sum(buf[pos + 4 : pos + 12]) & 0xFF != buf[pos + 12]:
                self.stats.crc_errors += 1
                pos += 1
                continue
            pos += FRAME_SIZE
            if self._last is not None and seq <= self._last:
                self.stats.duplicates += 1
                continue
            if self._last is not None and seq > self._last + 1:
                self.stats.lost_frames += seq - self._last - 1
                self.stats.gaps += 1
            self._last = seq
            seqs.append(seq)
            ticks.append(tick)
        del buf[:pos]
        self.stats.frames += len(seqs)
        return make_block(np.array(seqs), np.array(ticks), arrival_ns)

    def mark_discontinuity(self) -> None:
        self.discontinuities += 1
        self._last = None
        self._buf.clear()


def toy_decoder_for(metadata: dict[str, Any]) -> ToyDecoder:
    return ToyDecoder(metadata)


class FakeDevice:
    """A device of the Device protocol producing toy frames.

    Parameters
    ----------
    name : str
        Stream name.
    period_s : float
        Time between blocks.
    frames_per_block : int
        Frames per ``recv``.
    errors : dict of int to exception
        Raise this exception on the given ``recv`` call number (0-based).
    start_error : exception, optional
        Raised by ``start``.
    """

    def __init__(
        self,
        name: str,
        period_s: float = 0.002,
        frames_per_block: int = 2,
        errors: dict[int, BaseException] | None = None,
        start_error: BaseException | None = None,
    ) -> None:
        self.name = name
        self.stats = LinkStats()
        self.period_s = period_s
        self.frames_per_block = frames_per_block
        self.errors = dict(errors or {})
        self.start_error = start_error
        self.taps: list[WireTap] = []
        self.sent = bytearray()  # every byte handed to the taps
        self.calls = 0
        self.seq = 0
        self.started = False
        self.closed = False
        self.lock = threading.Lock()

    @property
    def spec(self) -> StreamSpec:
        return StreamSpec(
            self.name,
            "image2d",
            1,
            1,
            1 / (self.period_s / self.frames_per_block),
            TICK_HZ,
            values=("seq",),
            units=("1",),
        )

    def add_tap(self, tap: WireTap) -> None:
        self.taps.append(tap)

    def metadata(self) -> dict[str, Any]:
        return {"family": "toy", "spec": self.spec.to_dict()}

    def start(self) -> None:
        if self.start_error is not None:
            raise self.start_error
        now = time.monotonic_ns()
        for tap in self.taps:
            tap.on_tx(self.name, b"START\r", now)
            tap.on_rx(self.name, b"OKAY\r", now)
            tap.on_event(self.name, "started", {}, now)
        self.started = True

    def stop(self) -> None:
        if self.started:
            self.started = False
            for tap in self.taps:
                tap.on_event(self.name, "stopped", {}, time.monotonic_ns())

    def close(self) -> None:
        self.stop()
        self.closed = True

    def recv(self, timeout: float | None = None) -> FrameBlock | None:
        call = self.calls
        self.calls += 1
        if call in self.errors:
            raise self.errors[call]
        time.sleep(self.period_s)
        seqs = range(self.seq, self.seq + self.frames_per_block)
        self.seq += self.frames_per_block
        data = encode_frames(seqs)
        now = time.monotonic_ns()
        with self.lock:
            self.sent += data
        for tap in self.taps:
            tap.on_rx(self.name, data, now)
        self.stats.frames += len(seqs)
        self.stats.bytes += len(data)
        arr = np.array(seqs)
        return make_block(arr, arr * 5, now)


class ListSink:
    """Keeps what it receives; optionally slow or failing."""

    def __init__(self, name: str = "", delay_s: float = 0.0, fail: bool = False) -> None:
        if name:
            self.name = name
        self.delay_s = delay_s
        self.fail = fail
        self.frames: dict[str, int] = {}
        self.blocks = 0
        self.errors: list[tuple[str, BaseException]] = []
        self.started_with: list[Any] | None = None
        self.stopped = False

    def on_start(self, devices: list[Any]) -> None:
        self.started_with = list(devices)

    def on_block(self, stream: str, block: FrameBlock) -> None:
        if self.delay_s:
            time.sleep(self.delay_s)
        if self.fail:
            raise ValueError("sink failure")
        self.blocks += 1
        self.frames[stream] = self.frames.get(stream, 0) + len(block)

    def on_error(self, stream: str, exc: BaseException) -> None:
        self.errors.append((stream, exc))

    def stop(self) -> None:
        self.stopped = True
