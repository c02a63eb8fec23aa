"""WSX bulk bytes to frame blocks, live and from a recording's journal (wsx.md §5, §6).

The driver journals every bulk and interrupt transfer as it arrived; frames
(``WSXF``, length, CRC-32) and events (``WSXE``, 16 bytes) are self-delimiting, so
the decoder cuts them out of any split of the bytes and skips what is neither (a
short packet, a corrupt frame: a resync). Good frames of one block are decoded at
once with numpy. A block is ``linear1d``: markers x CCDs (S x 3, sensor-major) x
(centroid px, peak counts, firing time ns after the frame's start); ``flags`` holds
each reading's quality code, ``ticks`` the frame's start (device ns), ``status`` the
frame header's flags. ``seq`` is the frame number, continued across a collection
that starts again at 0 (after an unplug) so that it never goes back.
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Mapping
from typing import Any

import numpy as np

from spotlab.core.frames import FrameBlock
from spotlab.core.stats import LinkStats
from spotlab.drivers.wsx.protocol import (
    CCDS,
    EVENT_MAGIC,
    EVENT_SIZE,
    FRAME_MAGIC,
    HEADER,
    MISSING_BELOW,
    frame_size,
    marker_dtype,
)

LAYOUT = "wsx-bulk"
VALUES = ("centroid", "peak", "fire_ns")
UNITS = ("px", "counts", "ns")
_EVENT = struct.Struct("<4sHHII")
#: ``start_ns`` above this (292 years after power-up) does not fit a tick (int64): not a good frame.
_MAX_START_NS = (1 << 63) - 1


class WsxDecoder:
    """Frames of one hub with ``n_markers`` markers and ``n_sensors`` position sensors."""

    def __init__(self, n_markers: int, n_sensors: int, stats: LinkStats | None = None) -> None:
        self.n_markers, self.n_sensors = n_markers, n_sensors
        self.size = frame_size(n_markers, n_sensors)
        self.dtype = marker_dtype(n_sensors)
        self.stats = stats if stats is not None else LinkStats()
        self._buf = bytearray()
        self._last: int | None = None
        self._last_seq = -1
        self._offset = 0
        self._dropped = 0
        #: Collections that started again at frame 0.
        self.restarts = 0
        #: Interrupt events seen, by code.
        self.events: dict[int, int] = {}

    def feed(self, data: bytes, arrival_ns: int) -> FrameBlock:
        """Decode the complete frames in ``data`` after what is buffered."""
        self._buf += data
        good: list[bytes] = []
        buf = self._buf
        while len(buf) >= 4:
            magic = bytes(buf[:4])
            if magic == EVENT_MAGIC:
                if len(buf) < EVENT_SIZE:
                    break
                code = _EVENT.unpack_from(buf)[1]
                self.events[code] = self.events.get(code, 0) + 1
                del buf[:EVENT_SIZE]
                continue
            if magic != FRAME_MAGIC:
                self._skip(buf)
                continue
            if len(buf) < 8:
                break
            length = struct.unpack_from("<I", buf, 4)[0]
            if length != self.size:
                self._skip(buf)
                continue
            if len(buf) < length:
                break
            frame = bytes(buf[:length])
            if zlib.crc32(frame[:-4]) != struct.unpack_from("<I", frame, length - 4)[0]:
                self.stats.crc_errors += 1
                self._skip(buf)
                continue
            del buf[:length]
            good.append(frame)
        return self._block(good, arrival_ns)

    def _skip(self, buf: bytearray) -> None:
        """Drop bytes up to the next magic (one resync)."""
        self.stats.resyncs += 1
        cut = [i for i in (buf.find(FRAME_MAGIC, 1), buf.find(EVENT_MAGIC, 1)) if i > 0]
        n = min(cut) if cut else max(1, len(buf) - 3)
        self.stats.bytes_skipped += n
        del buf[:n]

    def _block(self, frames: list[bytes], arrival_ns: int) -> FrameBlock:
        m, s = self.n_markers, self.n_sensors
        if not frames:
            return FrameBlock.empty(m, s * CCDS, len(VALUES))
        heads = [HEADER.unpack_from(f) for f in frames]
        seqs, keep = [], []
        for i, h in enumerate(heads):
            if h[4] != m or h[5] != s or h[6] != CCDS or h[8] > _MAX_START_NS:
                # Not a good frame though its CRC holds: counted as a CRC error and skipped.
                self.stats.crc_errors += 1
                continue
            seq = self._accept(h[2], h[9])
            if seq is not None:
                seqs.append(seq)
                keep.append(i)
        if not keep:
            return FrameBlock.empty(m, s * CCDS, len(VALUES))
        raw = b"".join(frames[i][HEADER.size : HEADER.size + m * self.dtype.itemsize] for i in keep)
        rec = np.frombuffer(raw, dtype=self.dtype).reshape(len(keep), m)
        ccd = rec["ccd"].reshape(len(keep), m, s * CCDS)
        centroid = ccd["centroid"].astype(np.float64)
        centroid[centroid < MISSING_BELOW] = np.nan
        data = np.empty((len(keep), m, s * CCDS, len(VALUES)))
        data[..., 0] = centroid
        data[..., 1] = ccd["peak"]
        data[..., 2] = rec["fire_ns"][..., None]
        return FrameBlock(
            seq=np.asarray(seqs, dtype=np.int64),
            ticks=np.asarray([heads[i][8] for i in keep], dtype=np.int64),
            arrival_ns=np.full(len(keep), arrival_ns, dtype=np.int64),
            data=data,
            flags=ccd["code"].astype(np.uint8),
            status=np.asarray([heads[i][3] for i in keep], dtype=np.uint16),
        )

    def _accept(self, number: int, dropped: int) -> int | None:
        """The ``seq`` of frame ``number``; counts losses, device drops and restarts."""
        last = self._last
        if last is not None and number == last:
            self.stats.duplicates += 1
            return None
        if last is not None and number < last:  # a new collection (after an unplug)
            self.restarts += 1
            self.stats.gaps += 1
            self._offset = self._last_seq + 1 - number
            self._dropped = 0
        elif last is None and number + self._offset <= self._last_seq:
            self._offset = self._last_seq + 1 - number
            self._dropped = 0
        elif last is not None and number > last + 1:
            missing = number - last - 1
            by_device = max(0, min(missing, dropped - self._dropped))
            self.stats.device_dropped += by_device
            self.stats.lost_frames += missing - by_device
            self.stats.gaps += 1
        self._dropped = dropped
        self._last = number
        self._last_seq = number + self._offset
        self.stats.frames += 1
        return self._last_seq

    def summary(self) -> dict[str, Any]:
        """Figures for ``spotlab info``: restarts and the device's events."""
        return {"restarts": self.restarts, "events": {str(k): v for k, v in self.events.items()}}

    def mark_discontinuity(self) -> None:
        """Drop a partial frame; frame numbers are not joined across the break."""
        self._buf.clear()
        self._last = None


def decoder_from_metadata(meta: Mapping[str, Any]) -> WsxDecoder:
    """The decoder of a recorded WSX stream, from ``WsxDriver.metadata()``."""
    spec = meta["spec"]
    return WsxDecoder(int(spec["n_markers"]), int(spec["n_sensors"]) // CCDS)
