"""The device's transmit line: a FIFO of byte chunks paced at the baud rate.

A UART sends one byte per 10 bit times (start, 8 data, stop). Every chunk the
device queues (a reply, an event frame, a data frame, injected garbage) starts
when the line is free and its byte ``i`` is complete at
``start + (i + 1) * 10 / baud`` seconds. Nothing leaves the device faster than
that, whatever carries the bytes afterwards.

The line also applies the time-window faults: a burst damages every byte
that is on the line during its window, a disconnect loses them. Each chunk is
*resolved* exactly once — when its last byte has left, or when a reset throws
it away — and the owner's callback then does the accounting (fault log,
ground truth) from the chunk's final state.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

BIT_NS = 10 * 1_000_000_000  # ns * baud of one 10-bit character
ChunkKind = Literal["data", "event", "reply", "banner", "garbage"]
Outcome = Literal["intact", "damaged", "lost", "cut", "discarded"]


@dataclass
class Chunk:
    """Bytes queued on the line as one unit, with what happened to them.

    Attributes
    ----------
    data : bytearray
        The bytes as they go on the line (damage is applied in place).
    start_ns : int
        World ns when the first bit starts.
    baud : int
        Line rate while this chunk is sent.
    kind : str
        ``data``, ``event``, ``reply``, ``banner`` or ``garbage``.
    seq, frame_no : int
        Of a data frame; -1 otherwise.
    duplicate_of : int or None
        Fault id when this chunk is an injected extra copy of a data frame.
    damaged_by, lost_by, cut_by : int or None
        Id of the first fault that damaged, lost (disconnect) or cut (reset) it.
    tag : object
        Owner's bookkeeping (the ground-truth row of a data frame).
    released : int
        Bytes already handed to the transport.
    """

    data: bytearray
    start_ns: int
    baud: int
    kind: ChunkKind
    seq: int = -1
    frame_no: int = -1
    duplicate_of: int | None = None
    damaged_by: int | None = None
    lost_by: int | None = None
    cut_by: int | None = None
    tag: object = None
    released: int = 0

    def done_ns(self, i: int) -> int:
        """World ns at which byte ``i`` is completely on the line."""
        return self.start_ns + ((i + 1) * BIT_NS) // self.baud

    @property
    def end_ns(self) -> int:
        """World ns when the last byte is complete (``start_ns`` for an empty chunk)."""
        return self.done_ns(len(self.data) - 1) if self.data else self.start_ns

    def n_done(self, t_ns: int) -> int:
        """How many bytes are complete at world time ``t_ns``."""
        if t_ns < self.start_ns:
            return 0
        return min(len(self.data), ((t_ns - self.start_ns + 1) * self.baud - 1) // BIT_NS)

    def first_done_from(self, t_ns: int) -> int:
        """Index of the first byte complete at or after ``t_ns`` (may be ``len(data)``)."""
        if t_ns <= self.start_ns:
            return 0
        return min(len(self.data), max(0, -(-((t_ns - self.start_ns) * self.baud) // BIT_NS) - 1))

    def outcome(self) -> Outcome:
        """What the line did to this chunk, most serious first."""
        if self.cut_by is not None:
            return "cut"
        if self.lost_by is not None:
            return "lost"
        if self.damaged_by is not None:
            return "damaged"
        return "intact"


@dataclass
class Segment:
    """Bytes released to the transport: ``data`` sent at ``baud``, complete at ``end_ns``."""

    data: bytes
    baud: int
    end_ns: int


@dataclass
class _Window:
    t0: int
    t1: int
    fault_id: int
    rng: np.random.Generator | None = None


@dataclass
class TxLine:
    """The transmit FIFO. ``on_resolved(chunk, outcome)`` is called once per chunk."""

    on_resolved: Callable[[Chunk, Outcome], None]
    free_ns: int = 0
    chunks: deque[Chunk] = field(default_factory=deque)
    _bursts: list[_Window] = field(default_factory=list)
    _downs: list[_Window] = field(default_factory=list)

    def start_time(self, t_ready: int) -> int:
        """When a chunk queued at ``t_ready`` would start."""
        return max(t_ready, self.free_ns)

    def enqueue(
        self, data: bytes, t_ready: int, baud: int, kind: ChunkKind, **meta: object
    ) -> Chunk:
        """Queue ``data`` at world time ``t_ready``; returns the chunk (start time fixed now)."""
        chunk = Chunk(bytearray(data), self.start_time(t_ready), baud, kind, **meta)  # type: ignore[arg-type]
        self.free_ns = chunk.end_ns
        for w in self._bursts:
            self._damage(chunk, w)
        for w in self._downs:
            self._lose(chunk, w)
        self.chunks.append(chunk)
        return chunk

    def backlog(self, t_ns: int) -> int:
        """Bytes queued but not yet complete on the line at ``t_ns``."""
        total = 0
        for c in reversed(self.chunks):
            if c.end_ns <= t_ns:
                break
            total += len(c.data) - c.n_done(t_ns)
        return total

    def add_burst(self, t0: int, t1: int, fault_id: int, rng: np.random.Generator) -> None:
        """Damage (XOR with non-zero random bytes) every byte completing in [t0, t1)."""
        w = _Window(t0, t1, fault_id, rng)
        self._bursts.append(w)
        for c in self.chunks:
            self._damage(c, w)

    def add_down(self, t0: int, t1: int, fault_id: int) -> None:
        """Lose every byte completing in [t0, t1) (the link is disconnected)."""
        w = _Window(t0, t1, fault_id)
        self._downs.append(w)
        for c in self.chunks:
            self._lose(c, w)

    def is_down(self, t_ns: int) -> bool:
        """Is the link disconnected at ``t_ns``?"""
        return any(w.t0 <= t_ns < w.t1 for w in self._downs)

    def down_until(self, t_ns: int) -> int | None:
        """End of the disconnection that holds ``t_ns``, or None."""
        ends = [w.t1 for w in self._downs if w.t0 <= t_ns < w.t1]
        return max(ends) if ends else None

    def down_started_between(self, t0_ns: int, t1_ns: int) -> bool:
        """Did a disconnection begin in (t0_ns, t1_ns]?"""
        return any(t0_ns < w.t0 <= t1_ns for w in self._downs)

    def transitions_after(self, t_ns: int) -> int | None:
        """Next world time after ``t_ns`` when the link goes down or comes back."""
        times = [x for w in self._downs for x in (w.t0, w.t1) if x > t_ns]
        return min(times) if times else None

    def _range(self, c: Chunk, w: _Window) -> tuple[int, int]:
        if w.t1 <= c.start_ns or w.t0 > c.end_ns:
            return 0, 0
        return c.first_done_from(w.t0), c.first_done_from(w.t1)

    def _damage(self, c: Chunk, w: _Window) -> None:
        lo, hi = self._range(c, w)
        lo = max(lo, c.released)
        if hi > lo and w.rng is not None:
            mask = w.rng.integers(1, 256, size=hi - lo, dtype=np.uint8)
            view = np.frombuffer(c.data, dtype=np.uint8)
            view[lo:hi] ^= mask
            if c.damaged_by is None:
                c.damaged_by = w.fault_id

    def _lose(self, c: Chunk, w: _Window) -> None:
        lo, hi = self._range(c, w)
        if hi > lo and c.lost_by is None:
            c.lost_by = w.fault_id

    def _keep(self, c: Chunk, lo: int, hi: int) -> bytes:
        """Bytes lo..hi of ``c`` minus those that complete while the link is down."""
        if not self._downs:
            return bytes(c.data[lo:hi])
        out = bytearray()
        for i in range(lo, hi):
            if not self.is_down(c.done_ns(i)):
                out.append(c.data[i])
        return bytes(out)

    def release(self, now_ns: int) -> list[Segment]:
        """Bytes complete on the line by ``now_ns`` and not released before, in order."""
        segments: list[Segment] = []
        while self.chunks:
            c = self.chunks[0]
            n = c.n_done(now_ns)
            if n > c.released:
                data = self._keep(c, c.released, n)
                if data:
                    segments.append(Segment(data, c.baud, c.done_ns(n - 1)))
                c.released = n
            if c.released < len(c.data):
                break
            self.chunks.popleft()
            self.on_resolved(c, c.outcome())
        return segments

    def next_ns(self) -> int | None:
        """World ns when the next byte will be complete, or None when the FIFO is empty."""
        if not self.chunks:
            return None
        c = self.chunks[0]
        return c.done_ns(c.released) if c.released < len(c.data) else c.start_ns

    def cut(self, t_ns: int, fault_id: int | None) -> None:
        """A reset at ``t_ns``: bytes complete by then stay, the rest of the FIFO is thrown away.

        A chunk sent in part keeps its first bytes and is resolved ``cut`` once
        they are released; chunks not started are resolved ``discarded`` at once.
        ``fault_id`` (None for a commanded reset) is recorded in ``cut_by``.
        """
        kept: deque[Chunk] = deque()
        for c in self.chunks:
            n = c.n_done(t_ns)
            if n == len(c.data):
                kept.append(c)
            elif n > 0:
                del c.data[n:]
                c.cut_by = -1 if fault_id is None else fault_id
                kept.append(c)
            else:
                c.cut_by = -1 if fault_id is None else fault_id
                self.on_resolved(c, "discarded")
        self.chunks = kept
        self.free_ns = max([t_ns] + [c.end_ns for c in kept])


def garble(data: bytes, tx_baud: int, rx_baud: int, rng: np.random.Generator) -> bytes:
    """What a receiver set to ``rx_baud`` makes of ``data`` sent at ``tx_baud``.

    Equal rates pass the bytes through. Otherwise the receiver sees framing
    garbage: one byte per sent byte when it is faster than the sender, fewer
    (in proportion to the rates) when it is slower, with random values.
    """
    if tx_baud == rx_baud or not data:
        return data
    n = len(data) if rx_baud >= tx_baud else round(len(data) * rx_baud / tx_baud)
    return rng.integers(0, 256, size=n, dtype=np.uint8).tobytes()
