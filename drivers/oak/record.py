"""What the OAK driver journals: each matched frame's blobs as one self-checking record.

An OAK sends images over XLink, not bytes spotlab could record, and journalling
1280x800 images at 300 Hz would be 300 MB/s per camera. The driver journals what it
computed on the host instead: per frame, per camera, the timestamps and the blobs
of :func:`spotlab.imaging.find_blobs`. Layout (little-endian)::

    offset  size    field
    0       4       magic b"SOK1"
    4       4       uint32 seq, the driver's frame counter
    8       2       uint16 C, camera records that follow
    10      2       uint16 reserved (0)
    12      ...     C camera records:
                      uint8 camera (index in the stream), uint8 flags (bit 0 too many
                      blobs, bit 1 offline: no image, bit 2 flooded), uint16 n_blobs,
                      uint32 n_found (components before the gates), uint32 camera frame
                      counter, uint32 exposure (µs), int64 host ns, int64 device ns
                      (exposure mid-points), then n_blobs x (float64 x, float64 y px,
                      uint32 area px, uint16 peak, uint8 blob flags, 1 pad byte)
    end     4       uint32 CRC-32 (zlib) of every byte before it

The driver decodes its own records, so a replay gives the blocks it delivered live,
bit for bit. Frame block layout: docs/oak.md.
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from spotlab.core.errors import ConfigurationError
from spotlab.core.frames import FrameBlock
from spotlab.core.stats import LinkStats
from spotlab.core.streams import StreamSpec
from spotlab.imaging import Blobs

MAGIC = b"SOK1"
VALUES = ("x", "y", "area", "peak", "dt")
UNITS = ("px", "px", "px", "counts", "s")
#: Camera record flags.
CAM_TOO_MANY, CAM_OFFLINE, CAM_FLOODED = 1, 2, 4
#: Frame block flags beyond the blob flags of spotlab.imaging (bits 0-3).
FLAG_OFFLINE, FLAG_FLOODED = 0x10, 0x20

_HEAD = struct.Struct("<4sIHH")
_CAM = struct.Struct("<BBHIIIqq")
_BLOB = np.dtype(
    [("x", "<f8"), ("y", "<f8"), ("area", "<u4"), ("peak", "<u2"), ("flags", "u1"), ("pad", "u1")]
)


@dataclass(frozen=True)
class CameraShot:
    """One camera's part of a frame: its times and blobs, or offline (``blobs`` None)."""

    camera: int
    blobs: Blobs | None
    camera_seq: int = 0
    exposure_us: int = 0
    host_ns: int = 0
    device_ns: int = 0


def encode_frame(seq: int, shots: Sequence[CameraShot]) -> bytes:
    """One journal record of a matched frame.

    Parameters
    ----------
    seq : int
        Driver frame counter.
    shots : sequence of CameraShot
        One per camera of the stream, in camera order.
    """
    parts = [_HEAD.pack(MAGIC, seq & 0xFFFFFFFF, len(shots), 0)]
    for s in shots:
        b = s.blobs
        if b is None:
            parts.append(_CAM.pack(s.camera, CAM_OFFLINE, 0, 0, 0, 0, 0, 0))
            continue
        flags = (CAM_TOO_MANY if b.truncated else 0) | (CAM_FLOODED if b.flooded else 0)
        parts.append(
            _CAM.pack(
                s.camera,
                flags,
                len(b),
                min(b.n_components, 0xFFFFFFFF),
                s.camera_seq & 0xFFFFFFFF,
                s.exposure_us,
                s.host_ns,
                s.device_ns,
            )
        )
        rec = np.zeros(len(b), _BLOB)
        rec["x"], rec["y"], rec["area"] = b.x, b.y, b.area
        rec["peak"], rec["flags"] = np.minimum(b.peak, 0xFFFF), b.flags
        parts.append(rec.tobytes())
    body = b"".join(parts)
    return body + struct.pack("<I", zlib.crc32(body))


class OakRecordDecoder:
    """Records of :func:`encode_frame` to frame blocks, from any split of the bytes.

    Parameters
    ----------
    spec : StreamSpec
        The stream: ``n_sensors`` cameras, ``n_markers`` blob slots per camera.
    stats : LinkStats, optional
        Counters to update (the driver passes its own).
    """

    def __init__(self, spec: StreamSpec, stats: LinkStats | None = None) -> None:
        self.spec = spec
        self.stats = stats if stats is not None else LinkStats()
        self._buf = bytearray()
        self._last_seq: int | None = None

    def mark_discontinuity(self) -> None:
        """Do not count a gap in ``seq`` across a reconnect as lost frames."""
        self._last_seq = None

    def feed(self, data: bytes, arrival_ns: int) -> FrameBlock:
        """Decode the complete records in ``data`` after what is buffered."""
        self._buf += data
        rows: list[FrameBlock] = []
        while True:
            start = self._buf.find(MAGIC)
            if start < 0:
                self._skip(max(0, len(self._buf) - len(MAGIC) + 1))
                break
            self._skip(start)
            size = self._record_size()
            if size is None:
                break
            if size < 0:
                self._skip(1)
                continue
            body = bytes(self._buf[: size - 4])
            (crc,) = struct.unpack_from("<I", self._buf, size - 4)
            if zlib.crc32(body) != crc:
                self.stats.crc_errors += 1
                self._skip(1)
                continue
            del self._buf[:size]
            rows.append(self._block(body, arrival_ns))
        if not rows:
            return FrameBlock.empty(self.spec.n_markers, self.spec.n_sensors, len(VALUES))
        return rows[0] if len(rows) == 1 else FrameBlock.concat(rows)

    def _skip(self, n: int) -> None:
        if n:
            del self._buf[:n]
            self.stats.resyncs += 1
            self.stats.bytes_skipped += n

    def _record_size(self) -> int | None:
        """Bytes of the record at the buffer's start; None if incomplete, -1 if implausible."""
        if len(self._buf) < _HEAD.size:
            return None
        _, _, n_cams, _ = _HEAD.unpack_from(self._buf)
        if n_cams != self.spec.n_sensors:
            return -1
        pos = _HEAD.size
        for _ in range(n_cams):
            if len(self._buf) < pos + _CAM.size:
                return None
            n_blobs = _CAM.unpack_from(self._buf, pos)[2]
            if n_blobs > self.spec.n_markers:
                return -1
            pos += _CAM.size + n_blobs * _BLOB.itemsize
        pos += 4
        return pos if len(self._buf) >= pos else None

    def _block(self, body: bytes, arrival_ns: int) -> FrameBlock:
        m, c = self.spec.n_markers, self.spec.n_sensors
        data = np.full((1, m, c, len(VALUES)), np.nan)
        flags = np.zeros((1, m, c), np.uint8)
        seq, n_cams = _HEAD.unpack_from(body)[1:3]
        pos = _HEAD.size
        ticks: int | None = None
        status = 0
        for _ in range(n_cams):
            cam, cflags, n, _, _, _, host_ns, _ = _CAM.unpack_from(body, pos)
            pos += _CAM.size
            rec = np.frombuffer(body, _BLOB, count=n, offset=pos)
            pos += n * _BLOB.itemsize
            if cam >= c:
                continue
            if cflags & CAM_OFFLINE:
                flags[0, :, cam] = FLAG_OFFLINE
                status |= CAM_OFFLINE
                continue
            # Frame time: exposure mid-point of the lowest-numbered camera that delivered.
            ticks = host_ns if ticks is None else ticks
            status |= cflags
            data[0, :n, cam, 4] = (host_ns - ticks) / 1e9
            data[0, :n, cam, 0], data[0, :n, cam, 1] = rec["x"], rec["y"]
            data[0, :n, cam, 2], data[0, :n, cam, 3] = rec["area"], rec["peak"]
            flags[0, :n, cam] = rec["flags"]
            if cflags & CAM_FLOODED:
                flags[0, :, cam] |= FLAG_FLOODED
        self._count(seq)
        return FrameBlock(
            seq=np.array([seq], np.int64),
            ticks=np.array([0 if ticks is None else ticks], np.int64),
            arrival_ns=np.array([arrival_ns], np.int64),
            data=data,
            flags=flags,
            status=np.array([status], np.uint16),
        )

    def _count(self, seq: int) -> None:
        self.stats.frames += 1
        if self._last_seq is not None and seq > self._last_seq + 1:
            self.stats.lost_frames += seq - self._last_seq - 1
        self._last_seq = seq


def stream_spec(name: str, cameras: int, max_blobs: int, fps: float, **meta: Any) -> StreamSpec:
    """The ``blobs2d`` stream of an OAK driver (ticks: host monotonic ns)."""
    return StreamSpec(
        name=name, kind="blobs2d", n_sensors=cameras, n_markers=max_blobs, rate_hz=fps,
        tick_hz=1e9, values=VALUES, units=UNITS, metadata=dict(meta),
    )  # fmt: skip


def decoder_from_metadata(metadata: Mapping[str, Any]) -> OakRecordDecoder:
    """The decoder of a recorded OAK stream (for replay)."""
    if metadata.get("layout") != MAGIC.decode():
        raise ConfigurationError(f"not an OAK record stream: layout {metadata.get('layout')!r}")
    return OakRecordDecoder(StreamSpec.from_dict(dict(metadata["spec"])))
