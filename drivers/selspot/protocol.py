"""Host side of the SPX bytes: data frames to :class:`FrameBlock` (selspot.md §4).

A data frame (type ``0x01``) holds the MCS-1 prefix (frame_no, tick, status,
n_items), ``slot_us`` u16, ``n_leds`` u8, ``n_cams`` u8, then ``N x C`` records
of 5 bytes, LED-major. A record packs ``x | y << 12`` in 24 bits, the intensity
and the flags. :class:`SelspotDecoder` chains the MCS-1 frame decoder, a numpy
view of the frames through one structured dtype, and the sequence tracker; the
same object decodes a live link and a recording.
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
from spotlab.drivers.mcs1.decoding import PREFIX_FIELDS, Mcs1StreamDecoder, packed_dtype
from spotlab.drivers.mcs1.framing import FrameBatch, FrameDecoder
from spotlab.drivers.mcs1.metadata import as_config, recorded_config
from spotlab.drivers.mcs1.sequence import SequenceTracker
from spotlab.drivers.mcs1.version import VersionReply
from spotlab.drivers.selspot.config import SelspotConfig, led_table

log = logging.getLogger(__name__)

FRAME_TYPE = 0x01
FAMILY_CODE = "SPX"
VALUES = ("x", "y", "intensity")
UNITS = ("count", "count", "count")
#: Coordinate value meaning "no valid value".
INVALID = 0xFFF

#: Record flag bits (selspot.md §4).
FLAG_VALID = 0x01
FLAG_SATURATED = 0x02
FLAG_LOW_SIGNAL = 0x04
FLAG_AMBIENT_HIGH = 0x08
FLAG_NEAR_EDGE = 0x10
FLAG_SLOT_OVERRUN = 0x20
FLAG_AGC_LIMIT = 0x40


#: One record: the 24-bit coordinate word and the intensity read as one ``<u4``, then flags.
RECORD_DTYPE = np.dtype([("word", "<u4"), ("flags", "u1")])
#: Offset of ``n_items`` in a whole frame; ``n_items, slot_us, n_leds, n_cams`` follow.
_LAYOUT_OFFSET = 20


def frame_dtype(n_records: int) -> np.dtype[Any]:
    """Structured dtype of a whole SPX data frame with ``n_records`` records.

    Parameters
    ----------
    n_records : int
        ``N x C``.

    Returns
    -------
    numpy.dtype
        Packed, little-endian, ``28 + 5 n_records`` bytes. Field ``records``
        has shape (n_records,) of :data:`RECORD_DTYPE`. Fields ``layout_a``
        (u4: n_items, slot_us) and ``layout_b`` (u2: n_leds, n_cams) overlay the
        SPX header for a quick check of the whole layout.
    """
    fields = [
        *PREFIX_FIELDS,
        ("slot_us", "<u2", 22),
        ("n_leds", "u1", 24),
        ("n_cams", "u1", 25),
        ("records", (RECORD_DTYPE, (n_records,)), 26),
        ("pcrc", "<u2", 26 + 5 * n_records),
        ("layout_a", "<u4", _LAYOUT_OFFSET),
        ("layout_b", "<u2", _LAYOUT_OFFSET + 4),
    ]
    return packed_dtype(fields, 28 + 5 * n_records)


def decode_records(
    records: npt.NDArray[Any], n_leds: int, n_cams: int
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.uint8]]:
    """Unpack SPX records.

    Parameters
    ----------
    records : ndarray, shape (K, N * C, 5) of uint8 or (K, N * C) of RECORD_DTYPE
        Raw records, LED-major (LED 0 camera 0, LED 0 camera 1, ...).
    n_leds, n_cams : int
        ``N`` and ``C``.

    Returns
    -------
    data : ndarray of float64, shape (K, N, C, 3)
        x, y (detector counts 0-4094, 2048 on the optical axis; NaN unless the
        record is valid: flag bit 0 set and neither coordinate ``0xFFF``) and
        intensity (0-255, always given).
    flags : ndarray of uint8, shape (K, N, C)
        Record flags as sent.
    """
    if records.dtype != RECORD_DTYPE:
        records = np.ascontiguousarray(records, dtype=np.uint8).view(RECORD_DTYPE)[..., 0]
    word = records["word"]
    flags = records["flags"]
    x = word & 0xFFF
    y = (word >> 12) & 0xFFF
    invalid = (flags & FLAG_VALID) == 0
    invalid |= x == INVALID
    invalid |= y == INVALID
    k = records.shape[0]
    data = np.empty((k, n_leds * n_cams, 3), dtype=np.float64)
    data[..., 0] = x
    data[..., 1] = y
    data[..., 2] = word >> 24
    if invalid.any():
        data[..., :2][invalid] = np.nan
    return data.reshape(k, n_leds, n_cams, 3), np.ascontiguousarray(flags).reshape(
        k, n_leds, n_cams
    )


@dataclass(frozen=True)
class DeviceVersion(VersionReply):
    """What an SPX device says of itself in reply to ``VER:0`` (selspot.md §2).

    Attributes
    ----------
    firmware : str
        Firmware version (``"1.0"``).
    serial_number : str
        Serial number (``"SIM00042"``).
    max_cameras, max_leds : int
        Largest ``CAMS`` and ``LEDT`` the device accepts.
    text : str
        The whole reply text.
    """

    code = FAMILY_CODE
    form = "<max cameras> <max LEDs>"

    firmware: str
    serial_number: str
    max_cameras: int
    max_leds: int
    text: str


#: Parse a ``VER:0`` reply text (``ProtocolError`` if it is not the family's).
parse_version = DeviceVersion.parse


class SelspotDecoder(Mcs1StreamDecoder):
    """Bytes of an SPX link in, :class:`FrameBlock` out (a ``StreamDecoder``).

    Parameters
    ----------
    cameras : int
        Number of cameras ``C``.
    leds : int or sequence
        LED count ``N`` or the LED table (ids or ``(id, current)`` pairs).
    slot_us : int or None, optional
        Slot period the frames must report; ``None`` accepts any.
    stats : LinkStats, optional
        Counters to update; a new one by default.
    frame_period_us : float, optional
        Frame period in µs (``1e9 / rate_mhz``; :meth:`from_config` passes it).
        It bounds how far ``frame_no`` may advance for the ticks that passed
        (see :class:`~spotlab.drivers.mcs1.sequence.SequenceTracker`); without
        it the bound is a fixed 65536 frames.

    Attributes
    ----------
    stats : LinkStats
        Frames, losses, duplicates, gaps, CRC errors, resyncs, bytes.
    config_mismatches : int
        Frames dropped because their own header (``n_items``, ``n_leds``,
        ``n_cams``, ``slot_us``) contradicts the configuration; they also count
        as lost.

    Notes
    -----
    ``feed`` never raises on bad bytes: damage is counted in ``stats``.
    Frame ``arrival_ns`` is the stamp of the read that brought its last byte.
    Ticks are device µs (``tick_hz = 1e6``), unwrapped from 32 bits.
    """

    def __init__(
        self,
        cameras: int,
        leds: int | Any,
        slot_us: int | None = 100,
        *,
        stats: LinkStats | None = None,
        frame_period_us: float | None = None,
    ) -> None:
        n_leds = len(led_table(leds))
        if not (1 <= cameras <= 255 and 1 <= n_leds <= 255):
            raise ConfigurationError(f"cannot decode {cameras} cameras x {n_leds} LEDs")
        payload_len = 16 + 5 * n_leds * cameras
        self.n_cams = cameras
        self.n_leds = n_leds
        self.slot_us = slot_us
        self.frame_period_us = frame_period_us
        self.stats = stats if stats is not None else LinkStats()
        self.config_mismatches = 0
        self._frames = FrameDecoder(FRAME_TYPE, payload_len, self.stats)
        self._tracker = SequenceTracker(self.stats, frame_period_us)
        self._dtype = frame_dtype(n_leds * cameras)
        # n_items | slot_us << 16 and n_leds | n_cams << 8, as the frames must carry them
        self._layout_a = (n_leds * cameras) | ((slot_us or 0) << 16)
        self._layout_b = n_leds | (cameras << 8)

    @classmethod
    def from_config(
        cls, config: SelspotConfig | Mapping[str, Any], *, stats: LinkStats | None = None
    ) -> SelspotDecoder:
        """A decoder for a configuration (a :class:`SelspotConfig` or its ``to_dict()``)."""
        config = as_config(config, SelspotConfig)
        return cls(
            config.cameras,
            config.leds,
            config.slot_us,
            stats=stats,
            frame_period_us=1e9 / config.rate_mhz,
        )

    @property
    def frame_bytes(self) -> int:
        """Bytes of one data frame."""
        return self._frames.frame_len

    @property
    def frame_bytes_accepted(self) -> int:
        """Bytes of all good frames (data and event) so far."""
        return self._frames.frame_bytes_accepted

    def _mismatch(self, bad: npt.NDArray[Any]) -> None:
        """Count frames whose own header contradicts the configuration; log the first."""
        if not self.config_mismatches:
            first = bad[0]
            log.warning(
                "SPX frames contradict the configuration (%d LEDs x %d cameras, slot %s µs): "
                "frame says n_leds=%d n_cams=%d n_items=%d slot=%d; dropping such frames",
                self.n_leds,
                self.n_cams,
                self.slot_us,
                first["n_leds"],
                first["n_cams"],
                first["n_items"],
                first["slot_us"],
            )
        self.config_mismatches += bad.shape[0]

    def _decode(self, batch: FrameBatch) -> FrameBlock:
        if not len(batch):
            return FrameBlock.empty(self.n_leds, self.n_cams, 3)
        frames = np.ascontiguousarray(batch.frames).reshape(-1).view(self._dtype)
        layout_a = frames["layout_a"]
        if self.slot_us is None:
            layout_a = layout_a & 0xFFFF  # any slot: check n_items only
        ok = (layout_a == self._layout_a) & (frames["layout_b"] == self._layout_b)
        arrival = batch.arrival_ns
        if not ok.all():
            self._mismatch(frames[~ok])
            frames, arrival = frames[ok], arrival[ok]
            if not frames.shape[0]:
                return FrameBlock.empty(self.n_leds, self.n_cams, 3)
        keep, seq, ticks = self._tracker.update(frames["seq"], frames["frame_no"], frames["tick"])
        if not keep.all():
            frames, arrival, seq, ticks = frames[keep], arrival[keep], seq[keep], ticks[keep]
        data, flags = decode_records(frames["records"], self.n_leds, self.n_cams)
        return FrameBlock(
            seq=seq,
            ticks=ticks,
            arrival_ns=np.asarray(arrival, dtype=np.int64),
            data=data,
            flags=flags,
            status=frames["status"].astype(np.uint16),
        )


def decoder_from_metadata(meta: Mapping[str, Any]) -> SelspotDecoder:
    """Rebuild the decoder of a recorded SPX stream.

    ``meta`` is :meth:`SelspotDriver.metadata`, the stream's ``StreamSpec.to_dict()`` or the
    configuration's ``to_dict()`` (:func:`~spotlab.drivers.mcs1.metadata.recorded_config`,
    which raises ``ConfigurationError`` for another family's).
    """
    return SelspotDecoder.from_config(recorded_config(meta, "selspot", "SPX", ("cameras", "leds")))
