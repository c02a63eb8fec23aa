"""MCS-1 stream frames: find, check and cut them out of a byte stream (mcs1.md §4).

A frame is ``A5 5A | type u8 | version/flags u8 | seq u16 | len u16 | hcrc u16 |
payload | pcrc u16`` (little-endian), ``len + 12`` bytes. :class:`FrameDecoder`
keeps the bytes not yet decoded, returns every complete data frame of one type
and length as rows of a 2-D array, keeps event frames (replies while streaming)
apart, and counts what it had to throw away in a :class:`LinkStats`.

Resynchronisation follows the spec exactly: a header CRC failure (or a header
whose type, version or ``len`` does not fit) counts a CRC error and drops one
byte; a payload CRC failure counts a CRC error and drops the two sync bytes, so
that a valid frame hidden behind a corrupted header is still found. Each run of
bytes thrown away between two good frames counts as one resync.

Speed comes from checking whole runs of back-to-back frames at once ("trains"):
sync, type, length and header CRC of every frame of a run are checked with
numpy (the header CRC through per-byte lookup tables, CRC being affine), and
each payload CRC costs one call of the C ``binascii.crc_hqx``. Anything odd
falls back to the spec's one-candidate-at-a-time procedure.
"""

from __future__ import annotations

import binascii
import functools
from collections import deque
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from spotlab.core.crc import CRC16_INIT
from spotlab.core.errors import ConfigurationError
from spotlab.core.stats import LinkStats
from spotlab.drivers.mcs1.commands import BANNER

SYNC = b"\xa5\x5a"
HEADER_BYTES = 10
OVERHEAD = 12
EVENT_TYPE = 0x7F
PROTOCOL_VERSION = 1
MAX_PAYLOAD = 4096
#: Event frames kept for :meth:`FrameDecoder.take_events` (older ones are dropped).
MAX_EVENTS = 256
#: Fewest back-to-back frames for which the vectorised check pays off.
_TRAIN_MIN = 16

_crc = binascii.crc_hqx


@dataclass(frozen=True)
class EventFrame:
    """An event frame: a reply the device sent while streaming.

    Attributes
    ----------
    payload : bytes
        The reply exactly as outside a stream (text, CRC, CR).
    arrival_ns : int
        Host monotonic time of the read that brought the frame's last byte.
    """

    payload: bytes
    arrival_ns: int


@dataclass(frozen=True)
class FrameBatch:
    """Complete, checked data frames in arrival order.

    Attributes
    ----------
    frames : ndarray of uint8, shape (K, L)
        Whole frames, header and payload CRC included (``L = len + 12``).
    arrival_ns : ndarray of int64, shape (K,)
        Host monotonic time of the read that brought each frame's last byte.
    """

    frames: npt.NDArray[np.uint8]
    arrival_ns: npt.NDArray[np.int64]

    def __len__(self) -> int:
        return int(self.frames.shape[0])


@functools.lru_cache(maxsize=64)
def _header_crc_tables(frame_type: int, payload_len: int) -> tuple[int, npt.NDArray[np.uint16]]:
    """Header CRC of a data frame as ``c0 ^ T[0][b3] ^ T[1][b4] ^ T[2][b5]``
    (cached per configuration: every decoder of one frame layout shares them; read only).

    Only bytes 3 (version/flags) and 4-5 (seq) vary between the data frames of
    one configuration; CRC is affine in the message, so their contributions
    add up (XOR) independently.
    """
    base = bytearray(SYNC + bytes([frame_type, 0, 0, 0]) + payload_len.to_bytes(2, "little"))
    c0 = _crc(bytes(base), CRC16_INIT)
    tables = np.zeros((3, 256), dtype=np.uint16)
    for row, offset in enumerate((3, 4, 5)):
        for value in range(256):
            base[offset] = value
            tables[row, value] = _crc(bytes(base), CRC16_INIT) ^ c0
        base[offset] = 0
    tables.setflags(write=False)
    return c0, tables


class FrameDecoder:
    """Cuts checked MCS-1 frames out of a byte stream.

    Parameters
    ----------
    frame_type : int
        The data frame type of the family (``0x01`` for SPX).
    payload_len : int
        The payload length every data frame must have in the current
        configuration, 1 to 4096 bytes.
    stats : LinkStats, optional
        Counters to update (``crc_errors``, ``resyncs``, ``bytes_skipped``);
        a new one by default.

    Attributes
    ----------
    stats : LinkStats
        The counters.
    events : deque of EventFrame
        Event frames received and not yet taken (see :meth:`take_events`); the
        oldest are dropped beyond :data:`MAX_EVENTS`.
    banner_seen : bool
        Set when the reset banner ``RESET7DB2\\r`` showed up between frames
        (the device reset itself); the owner clears it.
    """

    def __init__(self, frame_type: int, payload_len: int, stats: LinkStats | None = None) -> None:
        if not 0 <= frame_type <= 0xFF or frame_type == EVENT_TYPE:
            raise ConfigurationError(f"invalid MCS-1 data frame type {frame_type:#x}")
        if not 1 <= payload_len <= MAX_PAYLOAD:
            raise ConfigurationError(
                f"MCS-1 payload length must be 1 to {MAX_PAYLOAD} bytes, got {payload_len}"
            )
        self.frame_type = frame_type
        self.payload_len = payload_len
        self.frame_len = payload_len + OVERHEAD
        self.stats = stats if stats is not None else LinkStats()
        self.events: deque[EventFrame] = deque(maxlen=MAX_EVENTS)
        self.banner_seen = False
        self._c0, self._tables = _header_crc_tables(frame_type, payload_len)
        self._buf = bytearray()
        self._base = 0  # stream offset of self._buf[0]
        self._need = 0  # buffered bytes needed before parsing can progress
        self._chunk_ends: list[int] = []  # stream offset one past each buffered chunk
        self._chunk_ns: list[int] = []
        self._in_skip = False
        self._skip_tail = b""
        self.frame_bytes_accepted = 0  # bytes of good data and event frames (for accounting)

    @property
    def buffered(self) -> int:
        """Bytes received and not yet decoded or discarded."""
        return len(self._buf)

    def take_events(self) -> list[EventFrame]:
        """The event frames received so far, removed from the decoder."""
        events = list(self.events)
        self.events.clear()
        return events

    def feed(self, data: bytes | bytearray | memoryview, arrival_ns: int) -> FrameBatch:
        """Add received bytes; return the data frames completed by them.

        Parameters
        ----------
        data : bytes-like
            Bytes as read from the link.
        arrival_ns : int
            Host monotonic time of that read, in ns.

        Returns
        -------
        FrameBatch
            Complete, checked data frames (possibly none). Never raises on bad bytes.
        """
        self._append(data, arrival_ns)
        if len(self._buf) < self._need:
            return self._empty()
        return self._parse(final=False)

    def feed_many(self, chunks: Iterable[tuple[bytes | bytearray | memoryview, int]]) -> FrameBatch:
        """Add several reads at once (replay); each keeps its own arrival stamp.

        Parameters
        ----------
        chunks : iterable of (bytes-like, int)
            ``(data, arrival_ns)`` in the order they were read.

        Returns
        -------
        FrameBatch
            As :meth:`feed` after the last chunk, in one decoding pass.
        """
        for data, arrival_ns in chunks:
            self._append(data, arrival_ns)
        if len(self._buf) < self._need:
            return self._empty()
        return self._parse(final=False)

    def flush(self) -> FrameBatch:
        """End of input (or the link went quiet): resolve what is buffered.

        A frame still waiting for bytes is taken as truncated (a CRC error; its
        two sync bytes are dropped and the rest searched again); bytes that
        cannot start a frame are discarded. The buffer is empty afterwards.
        """
        return self._parse(final=True)

    def discard(self) -> None:
        """Throw away the buffered bytes (the link broke: they cannot be completed)."""
        if self._buf:
            self._skip(bytes(self._buf), 0, len(self._buf))
            self._consume(len(self._buf))
        self._need = 0
        self._in_skip = False
        self._skip_tail = b""

    # -- internals -------------------------------------------------------------
    def _append(self, data: bytes | bytearray | memoryview, arrival_ns: int) -> None:
        if data:
            self._buf += data
            self._chunk_ends.append(self._base + len(self._buf))
            self._chunk_ns.append(int(arrival_ns))

    def _empty(self) -> FrameBatch:
        return FrameBatch(
            np.zeros((0, self.frame_len), dtype=np.uint8), np.zeros(0, dtype=np.int64)
        )

    def _skip(self, view: bytes, start: int, stop: int) -> None:
        """Discard ``view[start:stop]``: count it, and look for the reset banner in it."""
        if stop <= start:
            return
        self.stats.bytes_skipped += stop - start
        if not self._in_skip:
            self.stats.resyncs += 1
            self._in_skip = True
        text = self._skip_tail + view[start:stop]
        if BANNER in text:
            self.banner_seen = True
        self._skip_tail = text[-(len(BANNER) - 1) :]

    def _accepted(self, nbytes: int) -> None:
        self._in_skip = False
        self._skip_tail = b""
        self.frame_bytes_accepted += nbytes

    def _consume(self, n: int) -> None:
        del self._buf[:n]
        self._base += n
        ends = self._chunk_ends
        drop = 0
        while drop < len(ends) and ends[drop] <= self._base:
            drop += 1
        if drop:
            del ends[:drop]
            del self._chunk_ns[:drop]

    def _arrival(self, last_byte: npt.NDArray[np.int64]) -> npt.NDArray[np.int64]:
        """Arrival stamps of the chunks holding the given stream offsets."""
        idx = np.searchsorted(np.asarray(self._chunk_ends, dtype=np.int64), last_byte, "right")
        return np.asarray(self._chunk_ns, dtype=np.int64)[idx]

    def _train(self, view: bytes, mv: memoryview, pos: int, count: int) -> int:
        """How many back-to-back data frames from ``pos`` pass every check (at most ``count``)."""
        flen, plen = self.frame_len, self.payload_len
        arr = np.frombuffer(view, dtype=np.uint8, count=count * flen, offset=pos).reshape(
            count, flen
        )
        t = self._tables
        hcrc = self._c0 ^ t[0][arr[:, 3]] ^ t[1][arr[:, 4]] ^ t[2][arr[:, 5]]
        ok = (
            (arr[:, 0] == 0xA5)
            & (arr[:, 1] == 0x5A)
            & (arr[:, 2] == self.frame_type)
            & ((arr[:, 3] >> 4) == PROTOCOL_VERSION)
            & (arr[:, 6] == (plen & 0xFF))
            & (arr[:, 7] == (plen >> 8))
            & (hcrc == (arr[:, 8] | (arr[:, 9].astype(np.uint16) << 8)))
        )
        k = count if ok.all() else int(np.argmin(ok))
        if k == 0:
            return 0
        stored = arr[:k, -2] | (arr[:k, -1].astype(np.uint16) << 8)
        first = pos + HEADER_BYTES
        computed = np.fromiter(
            (_crc(mv[s : s + plen], CRC16_INIT) for s in range(first, first + k * flen, flen)),
            dtype=np.uint16,
            count=k,
        )
        good = computed == stored
        return k if good.all() else int(np.argmin(good))

    def _parse(self, final: bool) -> FrameBatch:
        view = bytes(self._buf)
        n = len(view)
        flen, plen, ftype = self.frame_len, self.payload_len, self.frame_type
        runs: list[tuple[int, int]] = []  # (start, frame count) of accepted data frames
        pos = 0
        need = 0
        with memoryview(view) as mv:
            while True:
                i = view.find(SYNC, pos)
                if i < 0:
                    keep = 1 if (not final and n > pos and view[-1] == 0xA5) else 0
                    self._skip(view, pos, n - keep)
                    pos = n - keep
                    need = n - pos + 1 if keep else 0
                    break
                self._skip(view, pos, i)
                pos = i
                avail = n - pos
                if avail >= _TRAIN_MIN * flen:
                    k = self._train(view, mv, pos, avail // flen)
                    if k:
                        runs.append((pos, k))
                        self._accepted(k * flen)
                        pos += k * flen
                        continue
                # One candidate at a time, as the spec describes.
                if avail < HEADER_BYTES:
                    if final:
                        self._skip(view, pos, n)
                        pos = n
                        break
                    need = HEADER_BYTES
                    break
                ctype, cver = view[pos + 2], view[pos + 3]
                clen = view[pos + 6] | (view[pos + 7] << 8)
                hcrc = view[pos + 8] | (view[pos + 9] << 8)
                header_ok = (
                    _crc(mv[pos : pos + 8], CRC16_INIT) == hcrc
                    and cver >> 4 == PROTOCOL_VERSION
                    and (
                        (ctype == ftype and clen == plen)
                        or (ctype == EVENT_TYPE and 1 <= clen <= MAX_PAYLOAD)
                    )
                )
                if not header_ok:
                    self.stats.crc_errors += 1
                    self._skip(view, pos, pos + 1)
                    pos += 1
                    continue
                total = clen + OVERHEAD
                if avail < total:
                    if final:  # truncated by the end of input
                        self.stats.crc_errors += 1
                        self._skip(view, pos, pos + 2)
                        pos += 2
                        continue
                    need = total
                    break
                end = pos + total
                pcrc = view[end - 2] | (view[end - 1] << 8)
                if _crc(mv[pos + HEADER_BYTES : end - 2], CRC16_INIT) != pcrc:
                    self.stats.crc_errors += 1
                    self._skip(view, pos, pos + 2)
                    pos += 2
                    continue
                self._accepted(total)
                if ctype == EVENT_TYPE:
                    stamp = self._arrival(np.array([self._base + end - 1], dtype=np.int64))
                    self.events.append(
                        EventFrame(view[pos + HEADER_BYTES : end - 2], int(stamp[0]))
                    )
                elif runs and runs[-1][0] + runs[-1][1] * flen == pos:
                    runs[-1] = (runs[-1][0], runs[-1][1] + 1)
                else:
                    runs.append((pos, 1))
                pos = end
        batch = self._collect(view, runs)
        self._consume(pos)
        self._need = need
        return batch

    def _collect(self, view: bytes, runs: list[tuple[int, int]]) -> FrameBatch:
        if not runs:
            return self._empty()
        flen = self.frame_len
        count = sum(k for _, k in runs)
        first_last = self._base + runs[0][0] + flen - 1
        ends = self._chunk_ends
        if len(ends) < 2 or first_last >= ends[-2]:
            # The usual case: every frame ended in the latest read.
            arrival = np.full(count, self._chunk_ns[-1], dtype=np.int64)
        else:
            last = np.concatenate(
                [np.arange(s + flen - 1, s + k * flen, flen, dtype=np.int64) for s, k in runs]
            )
            arrival = self._arrival(last + self._base)
        if len(runs) == 1:
            start, k = runs[0]
            frames = np.frombuffer(view, dtype=np.uint8, count=k * flen, offset=start)
        else:
            joined = b"".join(view[s : s + k * flen] for s, k in runs)
            frames = np.frombuffer(joined, dtype=np.uint8)
        return FrameBatch(frames.reshape(-1, flen), arrival)
