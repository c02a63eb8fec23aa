"""NatNet packets to frame blocks, live and from a recording's journal.

The driver journals every datagram it receives as it arrived; a packet's header
(u16 id, u16 size) makes the journal self-delimiting, so the decoder cuts packets
out of any split of the bytes. Frames (``NAT_FRAMEOFDATA``) of the recorded
marker set become rows of a ``point3d`` block: one sensor, the set's markers in
the model description's order, x, y, z in mm. ``seq`` is the NatNet frame number
(after Motive's numbers went back, as when a take restarts, plus an offset that
makes it go on after the last ``seq``: one gap, the frames kept),
``ticks`` the camera mid-exposure stamp (ticks of the server's high-resolution
clock; the timestamp in µs before NatNet 3), ``status`` the frame params. Server
info and model descriptions in the stream are skipped (the metadata holds them).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from spotlab.core.errors import ConfigurationError
from spotlab.core.frames import FrameBlock
from spotlab.core.stats import LinkStats
from spotlab.drivers.natnet.wire import (
    HEADER,
    MAJORS,
    MESSAGE_IDS,
    NAT_FRAMEOFDATA,
    FrameOfData,
    NatNetFormatError,
    Version,
    parse_frame,
)

#: What ``spotlab.drivers.natnet`` writes as ``layout`` in a recording's metadata.
LAYOUT = "natnet-datagrams"
#: A frame number at most this far behind the last one is a stale datagram (dropped as a
#: duplicate); further back, Motive started counting again (a restart: frames kept).
REORDER_WINDOW = 10


class NatNetDecoder:
    """Packets of one NatNet stream to frame blocks of its marker set.

    Parameters
    ----------
    version : tuple of int
        The server's NatNet version (major, minor).
    marker_set : str
        The marker set whose markers are the stream's.
    labels : sequence of str
        Its marker names (M).
    stats : LinkStats, optional
    keep_bodies : bool
        Keep every accepted frame's rigid bodies in :attr:`bodies` (replay of a
        recording's 6D; the live driver does not need them).
    """

    def __init__(
        self,
        version: Version,
        marker_set: str,
        labels: Sequence[str],
        stats: LinkStats | None = None,
        *,
        keep_bodies: bool = False,
    ) -> None:
        if version[0] not in MAJORS:
            raise ConfigurationError(f"NatNet {version[0]}.{version[1]} is not 3.x or 4.x")
        self.version = version
        self.marker_set = marker_set
        self.labels = tuple(labels)
        self.stats = stats if stats is not None else LinkStats()
        self._buf = bytearray()
        self._last: int | None = None
        self._last_seq = -1
        self._offset = 0
        #: Times Motive's frame numbers went back (a take restarted), frames kept.
        self.restarts = 0
        #: The last frame decoded (its rigid bodies, labelled markers, timecode).
        self.last_frame: FrameOfData | None = None
        self.keep_bodies = keep_bodies
        #: With ``keep_bodies``: (frame number, {rigid body id: pose (9,)}) per frame.
        self.bodies: list[tuple[int, dict[int, npt.NDArray[np.float64]]]] = []

    def feed(self, data: bytes, arrival_ns: int) -> FrameBlock:
        """Decode the complete packets in ``data`` after what is buffered."""
        self._buf += data
        rows: list[FrameOfData] = []
        seqs: list[int] = []
        while len(self._buf) >= HEADER.size:
            message_id, size = HEADER.unpack_from(self._buf)
            if message_id not in MESSAGE_IDS:
                del self._buf[:1]
                self.stats.resyncs += 1
                self.stats.bytes_skipped += 1
                continue
            if len(self._buf) < HEADER.size + size:
                break
            payload = bytes(self._buf[HEADER.size : HEADER.size + size])
            del self._buf[: HEADER.size + size]
            if message_id != NAT_FRAMEOFDATA:
                continue
            try:
                frame = parse_frame(payload, self.version)
            except NatNetFormatError:
                self.stats.crc_errors += 1
                continue
            seq = self._accept(frame.frame_number)
            if seq is not None:
                rows.append(frame)
                seqs.append(seq)
                if self.keep_bodies:
                    self.bodies.append((frame.frame_number, frame.rigid_bodies))
        return self._block(rows, seqs, arrival_ns)

    def _accept(self, number: int) -> int | None:
        """The ``seq`` of frame ``number``, or None for a repeat; counts losses and
        restarts."""
        last = self._last
        if last is not None and last - REORDER_WINDOW <= number <= last:
            self.stats.duplicates += 1  # a repeat, or a datagram overtaken: dropped
            return None
        if last is not None and number < last:  # Motive started counting again
            self.restarts += 1
            self.stats.gaps += 1
            self._offset = self._last_seq + 1 - number
        elif last is None and number + self._offset <= self._last_seq:
            self._offset = self._last_seq + 1 - number  # after a break: go on after it
        elif last is not None and number > last + 1:
            self.stats.lost_frames += number - last - 1
            self.stats.gaps += 1
        self._last = number
        self._last_seq = number + self._offset
        self.stats.frames += 1
        return self._last_seq

    def _block(self, rows: list[FrameOfData], seqs: list[int], arrival_ns: int) -> FrameBlock:
        m = len(self.labels)
        if not rows:
            return FrameBlock.empty(m, 1, 3)
        self.last_frame = rows[-1]
        n = len(rows)
        data = np.full((n, m, 1, 3), np.nan)
        for i, f in enumerate(rows):
            x = f.marker_sets.get(self.marker_set)
            if x is not None and x.shape[0] == m:
                data[i, :, 0] = x * 1000.0
        if self.version >= (3, 0):
            ticks = [f.stamps[0] for f in rows]
        else:
            ticks = [round(f.timestamp_s * 1e6) for f in rows]
        return FrameBlock(
            seq=np.asarray(seqs, dtype=np.int64),
            ticks=np.asarray(ticks, dtype=np.int64),
            arrival_ns=np.full(n, arrival_ns, dtype=np.int64),
            data=data,
            flags=np.zeros((n, m, 1), dtype=np.uint8),
            status=np.asarray([f.params for f in rows], dtype=np.uint16),
        )

    def summary(self) -> dict[str, Any]:
        """Figures for ``spotlab info``: the marker set, its labels, the NatNet version."""
        return {
            "natnet_version": f"{self.version[0]}.{self.version[1]}",
            "marker_set": self.marker_set,
            "labels": list(self.labels),
            "restarts": self.restarts,
        }

    def mark_discontinuity(self) -> None:
        """Drop a partial packet; frame numbers are not joined across the break."""
        self._buf.clear()
        self._last = None


def decoder_from_metadata(meta: Mapping[str, Any], *, keep_bodies: bool = False) -> NatNetDecoder:
    """The decoder of a recorded NatNet stream, from ``NatNetDriver.metadata()``."""
    version = meta["natnet_version"]
    return NatNetDecoder(
        (int(version[0]), int(version[1])),
        str(meta["marker_set"]),
        list(meta["labels"]),
        keep_bodies=keep_bodies,
    )
