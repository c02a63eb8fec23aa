"""What an LSL inlet journals: each pulled chunk as one self-checking record.

LSL has no wire bytes of its own that spotlab could record (liblsl speaks its
protocol inside), so the inlet journals what it received, in this layout
(little-endian)::

    offset  size   field
    0       4      magic  b"SLC1"
    4       4      uint32 F, samples in the chunk (>= 1)
    8       4      uint32 C, channels per sample
    12      8      float64 time correction (s) at the pull, NaN if unknown
    20      8 F    float64 timestamps: the sender's LSL clock (s)
    20+8F   8 F C  float64 values, sample-major
    end     4      uint32 CRC-32 (zlib) of every byte before it

The decoder turns records back into the same frame blocks the live inlet
delivered (the inlet decodes its own records), so a replay reproduces them.
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Mapping
from typing import Any

import numpy as np
import numpy.typing as npt

from spotlab.core.errors import ConfigurationError
from spotlab.core.frames import FrameBlock
from spotlab.core.stats import LinkStats
from spotlab.core.streams import StreamSpec

MAGIC = b"SLC1"
_HEAD = struct.Struct("<4sIId")
#: Largest chunk a record may declare (a guard against a damaged length field).
MAX_SAMPLES = 1 << 20


def encode_chunk(
    timestamps: npt.ArrayLike, values: npt.ArrayLike, time_correction_s: float = float("nan")
) -> bytes:
    """One journal record of a chunk.

    Parameters
    ----------
    timestamps : array_like of float, shape (F,)
        Sender LSL timestamps in s.
    values : array_like of float, shape (F, C)
        Samples.
    time_correction_s : float, optional
        The inlet's clock offset (sender to receiver LSL clock) when pulled.

    Raises
    ------
    ConfigurationError
        If the shapes disagree or the chunk is empty.
    """
    t = np.ascontiguousarray(timestamps, dtype="<f8")
    x = np.ascontiguousarray(values, dtype="<f8")
    if t.ndim != 1 or x.ndim != 2 or x.shape[0] != t.shape[0] or not len(t):
        raise ConfigurationError(
            f"a chunk needs F >= 1 times and (F, C) values, got {t.shape} and {x.shape}"
        )
    body = _HEAD.pack(MAGIC, t.shape[0], x.shape[1], time_correction_s) + t.tobytes() + x.tobytes()
    return body + struct.pack("<I", zlib.crc32(body))


class LslChunkDecoder:
    """Records of :func:`encode_chunk` to frame blocks, from any split of the bytes.

    Parameters
    ----------
    spec : StreamSpec
        The stream: its markers x sensors x values must equal the channel count.
    stats : LinkStats, optional
        Counters to update (the driver passes its own).

    Attributes
    ----------
    time_correction_s : float
        The last time correction read (NaN before any).
    corrections : list of (int, float)
        ``(seq of the chunk's first sample, time correction in s)`` each time it changed.
    """

    def __init__(self, spec: StreamSpec, stats: LinkStats | None = None) -> None:
        self.spec = spec
        self.shape = (spec.n_markers, spec.n_sensors, max(len(spec.values), 1))
        self.n_channels = int(np.prod(self.shape))
        self.stats = stats if stats is not None else LinkStats()
        self.time_correction_s = float("nan")
        self.corrections: list[tuple[int, float]] = []
        self._buf = bytearray()
        self._seq = 0

    def feed(self, data: bytes, arrival_ns: int) -> FrameBlock:
        """Decode the complete records in ``data`` after what is buffered."""
        self._buf += data
        blocks: list[FrameBlock] = []
        while True:
            start = self._buf.find(MAGIC)
            if start < 0:
                keep = len(MAGIC) - 1
                self._skip(max(0, len(self._buf) - keep))
                break
            if start:
                self._skip(start)
            if len(self._buf) < _HEAD.size:
                break
            _, n, c, tc = _HEAD.unpack_from(self._buf)
            if not 1 <= n <= MAX_SAMPLES or c != self.n_channels:
                self._skip(1)
                continue
            size = _HEAD.size + 8 * n * (1 + c) + 4
            if len(self._buf) < size:
                break
            body = bytes(self._buf[: size - 4])
            (crc,) = struct.unpack_from("<I", self._buf, size - 4)
            if zlib.crc32(body) != crc:
                self.stats.crc_errors += 1
                self._skip(1)
                continue
            del self._buf[:size]
            blocks.append(self._block(body, n, c, tc, arrival_ns))
        if not blocks:
            return FrameBlock.empty(*self.shape)
        return blocks[0] if len(blocks) == 1 else FrameBlock.concat(blocks)

    def _skip(self, n: int) -> None:
        if n:
            del self._buf[:n]
            self.stats.resyncs += 1
            self.stats.bytes_skipped += n

    def _block(self, body: bytes, n: int, c: int, tc: float, arrival_ns: int) -> FrameBlock:
        off = _HEAD.size
        t = np.frombuffer(body, "<f8", n, off)
        x = np.frombuffer(body, "<f8", n * c, off + 8 * n).astype(np.float64)
        if tc == tc and tc != self.time_correction_s:  # not NaN, and changed
            self.corrections.append((self._seq, float(tc)))
            self.time_correction_s = float(tc)
        seq = np.arange(self._seq, self._seq + n, dtype=np.int64)
        self._seq += n
        self.stats.frames += n
        return FrameBlock(
            seq=seq,
            ticks=np.round(t * 1e9).astype(np.int64),
            arrival_ns=np.full(n, arrival_ns, dtype=np.int64),
            data=x.reshape(n, *self.shape),
            flags=np.zeros((n, *self.shape[:2]), dtype=np.uint8),
            status=np.zeros(n, dtype=np.uint16),
        )

    def mark_discontinuity(self) -> None:
        """Drop a partial record; sequence numbers keep counting samples received."""
        self._buf.clear()


def decoder_from_metadata(meta: Mapping[str, Any]) -> LslChunkDecoder:
    """Rebuild the decoder of a recorded LSL stream from ``LslInletDriver.metadata()``.

    Raises
    ------
    ConfigurationError
        If the metadata belongs to another family or has no stream spec.
    """
    family = meta.get("family")
    if family not in (None, "lsl"):
        raise ConfigurationError(f"metadata of a {family!r} stream, not an lsl one")
    spec = meta.get("spec")
    if not isinstance(spec, Mapping):
        raise ConfigurationError(f"metadata holds no stream spec; keys found: {sorted(meta)}")
    return LslChunkDecoder(StreamSpec.from_dict(dict(spec)))
