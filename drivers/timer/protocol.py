"""Host side of the TMR bytes: timer data frames to :class:`FrameBlock` (timer.md §4).

A data frame (type ``0x04``) holds the MCS-1 prefix (frame_no, µs tick, status,
n_items = edge records used), the 64-bit 10 MHz counter, the input arming mask,
the count of edges lost, ``E`` (slots), the LTC timecode fields and ``E`` edge
records of 12 bytes. :class:`TimerDecoder` chains the MCS-1 frame decoder, a
numpy view of the frames through one structured dtype and the sequence
tracker; the same object decodes a live link and a recording.

FrameBlock layout of a ``timer`` stream (``E`` slots):

* ``ticks`` (F,): the 64-bit counter at each timer frame, 10 MHz ticks
  (``StreamSpec.tick_hz = 1e7``), exact int64;
* ``data`` (F, E + 1, 1, 4): rows ``0 .. E-1`` are the edge slots, values
  ``(channel, index, offset, rising)``: channel 0-7 an input, ``128 + k`` output
  ``k``; index: the channel's edge number since ``START:`` (unwrapped from 16
  bits); offset: the edge's counter minus the frame's (ticks, exact in
  float64, negative for edges the frame carries late); rising 1 or 0. Unused
  slots are NaN. Row ``E`` is the frame's LTC timecode:
  ``(seconds of day hh*3600+mm*60+ss, frames ff, fps, drop_frame)``, NaN when off;
* ``flags`` (F, E + 1, 1): the record flag byte (bit 0 rising) of used slots,
  ``0x80`` added for a used slot; row ``E``: ``tc_flags``;
* ``status`` (F,): the status word.

:func:`spotlab.drivers.timer.edges.extract_edges` turns blocks into flat edge arrays.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from spotlab.core.errors import ConfigurationError
from spotlab.core.frames import FrameBlock
from spotlab.core.stats import LinkStats
from spotlab.core.ticks import unwrap_counter
from spotlab.drivers.mcs1.decoding import PREFIX_FIELDS, Mcs1StreamDecoder, packed_dtype
from spotlab.drivers.mcs1.framing import FrameBatch, FrameDecoder
from spotlab.drivers.mcs1.metadata import as_config, recorded_config
from spotlab.drivers.mcs1.sequence import SequenceTracker
from spotlab.drivers.mcs1.version import VersionReply
from spotlab.drivers.timer.config import RECORD_BYTES, TimerConfig

log = logging.getLogger(__name__)

FRAME_TYPE = 0x04
FAMILY_CODE = "TMR"
TICK_HZ = 10_000_000
TICKS_PER_US = 10
VALUES = ("channel", "index", "offset", "rising")
UNITS = ("1", "count", "tick", "1")
#: Channel numbers from this on are output pulses (``128 + output``).
CHANNEL_OUTPUT = 0x80
#: Flag added in ``FrameBlock.flags`` to mark a used edge slot.
SLOT_USED = 0x80
EDGE_RISING = 0x01
TC_ON = 0x01
TC_DROP_FRAME = 0x02

RECORD_DTYPE = np.dtype([("tick", "<i8"), ("channel", "u1"), ("flags", "u1"), ("count", "<u2")])


def frame_dtype(n_slots: int) -> np.dtype[Any]:
    """Structured dtype of a whole TMR data frame with ``n_slots`` edge slots.

    Returns
    -------
    numpy.dtype
        Packed, little-endian, ``44 + 12 n_slots`` bytes; ``records`` has shape
        (n_slots,) of :data:`RECORD_DTYPE`.
    """
    fields: list[tuple[str, Any, int]] = [
        *PREFIX_FIELDS,
        ("counter", "<i8", 22),
        ("armed", "<u2", 30),
        ("edges_lost", "<u2", 32),
        ("n_slots", "u1", 34),
        ("tc_flags", "u1", 35),
        ("tc_fps", "u1", 36),
        ("tc", ("u1", (4,)), 37),
        ("records", (RECORD_DTYPE, (n_slots,)), 42),
        ("pcrc", "<u2", 42 + RECORD_BYTES * n_slots),
    ]
    return packed_dtype(fields, 44 + RECORD_BYTES * n_slots)


@dataclass(frozen=True)
class TimerVersion(VersionReply):
    """What a TMR unit says of itself in reply to ``VER:0`` (timer.md §2)."""

    code = FAMILY_CODE
    form = "<inputs> <outputs> <tick Hz>"

    firmware: str
    serial_number: str
    inputs: int
    outputs: int
    tick_hz: int
    text: str


#: Parse a ``VER:0`` reply text (``ProtocolError`` if it is not the family's).
parse_version = TimerVersion.parse


class TimerDecoder(Mcs1StreamDecoder):
    """Bytes of a TMR link in, :class:`FrameBlock` out (a ``StreamDecoder``).

    Parameters
    ----------
    slots : int
        Edge slots per frame ``E`` the frames must carry.
    stats : LinkStats, optional
        Counters to update; a new one by default.
    frame_period_us : float, optional
        Frame period in µs, for the frame-number plausibility check.

    Attributes
    ----------
    stats : LinkStats
        Frames, losses, duplicates, gaps, CRC errors, resyncs, bytes.
    config_mismatches : int
        Frames dropped because their header contradicts ``E`` (or says more
        records are used than there are slots).
    edges_lost : int
        The unit's count of edges dropped for lack of room, in the latest frame
        (cumulative since ``START:``, unwrapped from 16 bits).
    armed : int
        Arming mask of the latest frame.

    Notes
    -----
    ``feed`` never raises on bad bytes: damage is counted in ``stats``. See the
    module docstring for the block layout.
    """

    def __init__(
        self,
        slots: int,
        *,
        stats: LinkStats | None = None,
        frame_period_us: float | None = None,
    ) -> None:
        if not 1 <= slots <= 64:
            raise ConfigurationError(f"cannot decode timer frames of {slots} edge slots")
        self.slots = slots
        self.stats = stats if stats is not None else LinkStats()
        self.config_mismatches = 0
        self.edges_lost = 0
        self.armed = 0
        self._frames = FrameDecoder(FRAME_TYPE, 32 + RECORD_BYTES * slots, self.stats)
        self._tracker = SequenceTracker(self.stats, frame_period_us)
        self._dtype = frame_dtype(slots)
        self._counts: dict[int, int] = {}
        self._lost_last: int | None = None

    @classmethod
    def from_config(
        cls, config: TimerConfig | Mapping[str, Any], *, stats: LinkStats | None = None
    ) -> TimerDecoder:
        """A decoder for a configuration (a :class:`TimerConfig` or its ``to_dict()``)."""
        config = as_config(config, TimerConfig)
        return cls(config.slots, stats=stats, frame_period_us=1e9 / config.rate_mhz)

    def mark_discontinuity(self) -> None:
        """The link was broken or the stream restarted: counters (and edge counts) from 0."""
        super().mark_discontinuity()
        self._counts.clear()
        self._lost_last = None

    def _empty(self) -> FrameBlock:
        return FrameBlock.empty(self.slots + 1, 1, len(VALUES))

    def _decode(self, batch: FrameBatch) -> FrameBlock:
        if not len(batch):
            return self._empty()
        frames = np.ascontiguousarray(batch.frames).reshape(-1).view(self._dtype)
        arrival = batch.arrival_ns
        ok = (frames["n_slots"] == self.slots) & (frames["n_items"] <= self.slots)
        if not ok.all():
            if not self.config_mismatches:
                log.warning(
                    "TMR frames contradict the configuration (%d slots): frame says "
                    "n_slots=%d n_items=%d; dropping such frames",
                    self.slots,
                    frames[~ok][0]["n_slots"],
                    frames[~ok][0]["n_items"],
                )
            self.config_mismatches += int((~ok).sum())
            frames, arrival = frames[ok], arrival[ok]
            if not frames.shape[0]:
                return self._empty()
        restarts = self._tracker.restarts
        keep, seq, _ = self._tracker.update(frames["seq"], frames["frame_no"], frames["tick"])
        if self._tracker.restarts != restarts:
            self._counts.clear()
        if not keep.all():
            frames, arrival, seq = frames[keep], arrival[keep], seq[keep]
        data, flags = self._records(frames)
        return FrameBlock(
            seq=seq,
            ticks=frames["counter"].astype(np.int64),
            arrival_ns=np.asarray(arrival, dtype=np.int64),
            data=data,
            flags=flags,
            status=frames["status"].astype(np.uint16),
        )

    def _records(
        self, frames: npt.NDArray[Any]
    ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.uint8]]:
        f, e = frames.shape[0], self.slots
        if f == 0:  # every frame of the batch was dropped (a header contradicting E)
            return np.full((0, e + 1, 1, len(VALUES)), np.nan), np.zeros((0, e + 1, 1), np.uint8)
        rec = frames["records"]
        used = np.arange(e)[None, :] < frames["n_items"][:, None]
        data = np.full((f, e + 1, 1, len(VALUES)), np.nan)
        flags = np.zeros((f, e + 1, 1), dtype=np.uint8)
        channel = rec["channel"].astype(np.int64)
        index = np.zeros((f, e), dtype=np.int64)
        # Per channel, the 16-bit counts in capture order, unwrapped across blocks.
        chan_used = channel[used]
        count_used = rec["count"][used].astype(np.int64)
        index_used = np.zeros_like(count_used)
        for ch in np.unique(chan_used).tolist():
            sel = chan_used == ch
            out = unwrap_counter(count_used[sel], 16, self._counts.get(ch))
            index_used[sel] = out
            self._counts[ch] = int(out[-1])
        index[used] = index_used
        offset = rec["tick"] - frames["counter"][:, None]
        edges = data[:, :e, 0, :]
        edges[..., 0] = np.where(used, channel, np.nan)
        edges[..., 1] = np.where(used, index, np.nan)
        edges[..., 2] = np.where(used, offset, np.nan)
        edges[..., 3] = np.where(used, rec["flags"] & EDGE_RISING, np.nan)
        flags[:, :e, 0] = np.where(used, rec["flags"] | SLOT_USED, 0)
        tc_on = (frames["tc_flags"] & TC_ON) != 0
        tc = frames["tc"].astype(np.float64)
        tc_row = data[:, e, 0, :]
        tc_row[:, 0] = np.where(tc_on, tc[:, 0] * 3600 + tc[:, 1] * 60 + tc[:, 2], np.nan)
        tc_row[:, 1] = np.where(tc_on, tc[:, 3], np.nan)
        tc_row[:, 2] = np.where(tc_on, frames["tc_fps"], np.nan)
        tc_row[:, 3] = np.where(tc_on, (frames["tc_flags"] & TC_DROP_FRAME) != 0, np.nan)
        flags[:, e, 0] = frames["tc_flags"]
        lost = unwrap_counter(frames["edges_lost"], 16, self._lost_last)
        self._lost_last = int(lost[-1])
        self.edges_lost = self._lost_last
        self.armed = int(frames["armed"][-1])
        return data, flags


def decoder_from_metadata(meta: Mapping[str, Any]) -> TimerDecoder:
    """Rebuild the decoder of a recorded TMR stream.

    ``meta`` is :meth:`TimerDriver.metadata`, the stream's ``StreamSpec.to_dict()`` or the
    configuration's ``to_dict()`` (:func:`~spotlab.drivers.mcs1.metadata.recorded_config`,
    which raises ``ConfigurationError`` for another family's).
    """
    return TimerDecoder.from_config(recorded_config(meta, "timer", "TMR", ("slots",)))
