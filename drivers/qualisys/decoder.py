"""QTM data packets to frame blocks: the labelled 3-D markers, live and in replay.

The journal holds the bytes QTM sent (the driver records them raw, like every
family). The decoder cuts packets out of them (:class:`PacketSplitter`), keeps
the Data packets' 3D component and notes the rest (Event packets in
``events``, 6D bodies of the last frame in ``last_bodies``); Command and XML
packets, such as a reconnection's dialogue, are skipped.

FrameBlock layout (StreamSpec kind ``point3d``, one sensor, ``M`` labels):

* ``seq`` (F,): QTM's frame number, unwrapped from 32 bits; a frame number
  going back (QTM started a new capture) continues after the last ``seq``
  and counts a gap;
* ``ticks`` (F,): QTM's timestamp in µs (``tick_hz = 1e6``);
* ``data`` (F, M, 1, 3): x, y, z in mm in the order of the labels, NaN where
  the marker was not seen;
* ``flags`` (F, M, 1): 0x80 where the marker was seen; ``status`` 0.

Frame numbers skipping ahead within a stream are counted in ``lost_frames``
(QTM lost them: over TCP the host loses nothing) and one gap each.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from spotlab.core.errors import ConfigurationError, ProtocolError
from spotlab.core.frames import FrameBlock
from spotlab.core.stats import LinkStats
from spotlab.core.streams import StreamSpec
from spotlab.drivers.qualisys.protocol import (
    COMP_3D,
    COMP_6D,
    DATA,
    EVENT,
    EVENTS,
    F64,
    PacketSplitter,
    bodies_6d_from,
    markers_3d_from,
    parse_data,
)

FLAG_SEEN = 0x80


class QualisysDecoder:
    """QTM's bytes to :class:`FrameBlock` of labelled 3-D markers, from any split of them.

    Parameters
    ----------
    n_markers : int
        Labels in QTM's 3D parameters (the 3D component must carry as many).
    stats : LinkStats, optional
        Counters to update (the driver passes its own).
    keep_bodies : bool
        Keep every kept frame's 6D bodies in ``bodies`` (for :func:`bodies_from_recording`).

    Attributes
    ----------
    events : list of (int, int, str)
        ``(seq of the next frame, event number, name)`` of each Event packet.
    last_bodies : tuple of ndarray or None
        The last frame's 6D bodies: positions (B, 3) mm and rotations (B, 3, 3).
    packets : dict
        Count of packets by type number.
    config_mismatches : int
        Frames whose 3D component holds another number of markers (dropped).
    bodies : list of (int, ndarray, ndarray)
        With ``keep_bodies``: ``(seq, positions (B, 3), rotations (B, 3, 3))`` per frame
        that carried a 6D component.
    """

    def __init__(
        self, n_markers: int, stats: LinkStats | None = None, *, keep_bodies: bool = False
    ) -> None:
        self.n_markers = n_markers
        self.stats = stats if stats is not None else LinkStats()
        self.events: list[tuple[int, int, str]] = []
        self.last_bodies: tuple[F64, F64] | None = None
        self.packets: dict[int, int] = {}
        self.config_mismatches = 0
        self.malformed = 0
        self.keep_bodies = keep_bodies
        self.bodies: list[tuple[int, F64, F64]] = []
        self._split = PacketSplitter()
        self._last_frame: int | None = None
        self._last_seq = -1
        self._offset = 0
        self._fresh = True

    def feed(self, data: bytes, arrival_ns: int) -> FrameBlock:
        """Decode the complete packets in ``data`` after what is buffered."""
        bad, resyncs = self._split.bad_bytes, self._split.resyncs
        packets = self._split.feed(data)
        self.stats.bytes_skipped += self._split.bad_bytes - bad
        self.stats.resyncs += self._split.resyncs - resyncs
        seqs: list[int] = []
        ticks: list[int] = []
        rows: list[F64] = []
        for p in packets:
            self.packets[p.kind] = self.packets.get(p.kind, 0) + 1
            if p.kind == EVENT and p.body:
                code = p.body[0]
                self.events.append((self._last_seq + 1, code, EVENTS.get(code, f"event {code}")))
            if p.kind != DATA:
                continue
            try:
                frame = parse_data(p.body)
                xyz = markers_3d_from(frame.components[COMP_3D])
                six = frame.components.get(COMP_6D)
                bodies = bodies_6d_from(six) if six is not None else None
            except (ProtocolError, KeyError, ValueError):
                self.malformed += 1
                self.stats.crc_errors += 1
                continue
            if xyz.shape[0] != self.n_markers:
                self.config_mismatches += 1
                continue
            seqs.append(self._sequence(frame.frame))
            if bodies is not None:
                self.last_bodies = bodies
                if self.keep_bodies:
                    self.bodies.append((seqs[-1], *bodies))
            ticks.append(frame.timestamp_us)
            rows.append(xyz)
        n = len(seqs)
        self.stats.frames += n
        data_arr = np.array(rows, dtype=np.float64).reshape(n, self.n_markers, 1, 3)
        flags = np.where(np.isfinite(data_arr).all(axis=3), FLAG_SEEN, 0).astype(np.uint8)
        return FrameBlock(
            seq=np.array(seqs, dtype=np.int64),
            ticks=np.array(ticks, dtype=np.int64),
            arrival_ns=np.full(n, arrival_ns, dtype=np.int64),
            data=data_arr,
            flags=flags,
            status=np.zeros(n, dtype=np.uint16),
        )

    def _sequence(self, frame: int) -> int:
        """Unwrapped sequence number of QTM frame number ``frame``; counts losses."""
        last = self._last_frame
        self._last_frame = frame
        if last is None or self._fresh:
            self._fresh = False
            if self._last_seq >= 0:
                self._offset = self._last_seq + 1 - frame if frame <= self._last_seq else 0
            seq = frame + self._offset
        else:
            step = (frame - last) % (1 << 32)
            if step == 0 or step >= 1 << 31:  # a repeat, or QTM started anew
                self.stats.gaps += 1
                self._offset = self._last_seq + 1 - frame
                seq = frame + self._offset
            else:
                if step > 1:
                    self.stats.lost_frames += step - 1
                    self.stats.gaps += 1
                seq = self._last_seq + step
        self._last_seq = seq
        return seq

    def mark_discontinuity(self) -> None:
        """The connection was lost or made again: forget a partial packet; the next frame
        starts a new piece (frames missed in between are not counted as lost)."""
        self._split.clear()
        self._fresh = True

    def summary(self) -> dict[str, Any]:
        """Packet and event counts for ``spotlab info --json``."""
        return {
            "packets": {str(k): v for k, v in sorted(self.packets.items())},
            "events": [name for _, _, name in self.events],
            "config_mismatches": self.config_mismatches,
            "malformed": self.malformed,
        }


def decoder_from_metadata(meta: Mapping[str, Any]) -> QualisysDecoder:
    """Rebuild the decoder of a recorded QTM stream from ``QualisysDriver.metadata()``.

    Raises
    ------
    ConfigurationError
        If the metadata belongs to another family or has no stream spec.
    """
    family = meta.get("family")
    if family not in (None, "qualisys"):
        raise ConfigurationError(f"metadata of a {family!r} stream, not a qualisys one")
    spec = meta.get("spec")
    if not isinstance(spec, Mapping):
        raise ConfigurationError(f"metadata holds no stream spec; keys found: {sorted(meta)}")
    return QualisysDecoder(StreamSpec.from_dict(dict(spec)).n_markers)
