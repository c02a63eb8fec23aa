"""CSX stream decoding (coda.md §4): scanner frames into :class:`FrameBlock`.

Block layout for a table of ``M`` markers (``S = M + 4`` record slots):

* ``data`` (F, M + S, 1, 10) float64, values :data:`VALUES`
  ``(id, x, y, z, alpha_a, alpha_b, beta, dt_a, dt_b, dt_c)`` in units
  :data:`UNITS` (id; mm in the scanner frame of coda.md §1; rad; µs after the
  scan start). Rows ``0..M-1`` are the table's markers in table order: the one
  record of that ID the unit did not flag (bits 4-6: colour ambiguous,
  aliased, ghost), NaN when there is none. Rows ``M..M+S-1`` hold every other
  used record in frame order (flagged ones, IDs outside the table, a second
  unflagged record of one ID): **a flagged record never lands in a marker's
  row**. ``x, y, z`` are NaN unless the record is ``3D valid`` (and in RAW
  mode); angles and crossing times NaN where a mirror did not see the marker
  (and in 3D mode);
* ``flags`` (F, M + S, 1) uint8: the record's flag byte, 0 for an empty row
  (bit 7, never set on the wire, is added: row used);
* ``status`` (F,); ``ticks``: device µs at the scan start, unwrapped.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from spotlab.core.errors import ConfigurationError
from spotlab.core.frames import FrameBlock
from spotlab.core.stats import LinkStats
from spotlab.drivers.coda.config import MODES, SPARE_SLOTS, CodaConfig, record_bytes
from spotlab.drivers.mcs1.decoding import PREFIX_FIELDS, Mcs1StreamDecoder, packed_dtype
from spotlab.drivers.mcs1.framing import FrameBatch, FrameDecoder
from spotlab.drivers.mcs1.metadata import as_config, recorded_config
from spotlab.drivers.mcs1.sequence import SequenceTracker
from spotlab.drivers.mcs1.version import VersionReply

log = logging.getLogger(__name__)

FRAME_TYPE = 0x02
FAMILY_CODE = "CSX"
TICK_HZ = 1_000_000
VALUES = ("id", "x", "y", "z", "alpha_a", "alpha_b", "beta", "dt_a", "dt_b", "dt_c")
UNITS = ("1", "mm", "mm", "mm", "rad", "rad", "rad", "us", "us", "us")
COUNTS = 16_000
CENTRE_COUNT = 8_000
FOV_RAD = math.radians(40.0)
NOT_SEEN = 0xFFFF
F_3D_VALID = 0x01
F_SUSPECT = 0x70  # colour ambiguous | aliased | ghost suspected
ROW_USED = 0x80


def record_dtype(mode: str) -> np.dtype[Any]:
    """Structured dtype of one record in output ``mode`` (packed, little-endian)."""
    fields: list[tuple[str, Any]] = [("id", "u1"), ("flags", "u1")]
    if MODES[mode] & 1:
        fields.append(("xyz", ("<i4", (3,))))
    if MODES[mode] & 2:
        fields += [("counts", ("<u2", (3,))), ("dt", ("<u2", (3,)))]
    dt = np.dtype(fields)
    assert dt.itemsize == record_bytes(mode)
    return dt


def frame_dtype(n_markers: int, mode: str) -> np.dtype[Any]:
    """Structured dtype of a whole CSX data frame (``28 + (M + 4) R`` bytes)."""
    slots = n_markers + SPARE_SLOTS
    r = record_bytes(mode)
    fields: list[tuple[str, Any, int]] = [
        *PREFIX_FIELDS,
        ("mode", "u1", 22),
        ("n_slots", "u1", 23),
        ("n_markers", "u1", 24),
        ("limit", "u1", 25),
        ("records", (record_dtype(mode), (slots,)), 26),
        ("pcrc", "<u2", 26 + r * slots),
    ]
    return packed_dtype(fields, 28 + r * slots)


def counts_to_rad(counts: npt.NDArray[Any]) -> npt.NDArray[np.float64]:
    """Angle counts to radians (coda.md §1); NaN for ``0xFFFF``."""
    c = counts.astype(np.float64)
    return np.where(counts == NOT_SEEN, np.nan, (c - CENTRE_COUNT) * (FOV_RAD / COUNTS))


@dataclass(frozen=True)
class CodaVersion(VersionReply):
    """What a CSX unit says of itself in reply to ``VER:0``: its geometry (coda.md §3)."""

    code = FAMILY_CODE
    form = "<base um> <counts> <field mdeg>"

    firmware: str
    serial_number: str
    base_um: int
    counts: int
    fov_mdeg: int
    text: str


#: Parse a ``VER:0`` reply text (``ProtocolError`` if it is not the family's).
parse_version = CodaVersion.parse


class CodaDecoder(Mcs1StreamDecoder):
    """Bytes of a CSX link in, :class:`FrameBlock` out (a ``StreamDecoder``).

    Parameters
    ----------
    markers : tuple of int
        Marker IDs of the table, in table order.
    mode : str
        ``3D``, ``RAW`` or ``BOTH``.
    stats : LinkStats, optional
        Counters to update; a new one by default.
    frame_period_us : float, optional
        Scan period in µs, for the frame-number plausibility check.

    Attributes
    ----------
    config_mismatches : int
        Frames dropped because their header contradicts the configuration.
    suspect_records : int
        Records put in the unidentified rows so far.

    Notes
    -----
    ``feed`` never raises on bad bytes: damage is counted in ``stats``. See the
    module docstring for the block layout.
    """

    def __init__(
        self,
        markers: tuple[int, ...],
        mode: str,
        *,
        stats: LinkStats | None = None,
        frame_period_us: float | None = None,
    ) -> None:
        if not 1 <= len(markers) <= 56 or mode not in MODES:
            raise ConfigurationError(f"cannot decode CSX frames of {markers} in mode {mode!r}")
        self.markers = tuple(markers)
        self.mode = mode
        self.stats = stats if stats is not None else LinkStats()
        self.config_mismatches = 0
        self.suspect_records = 0
        m = len(markers)
        self.rows = m + m + SPARE_SLOTS
        self._row_of_id = np.full(256, -1, dtype=np.int64)
        self._row_of_id[list(markers)] = np.arange(m)
        self._dtype = frame_dtype(m, mode)
        self._frames = FrameDecoder(FRAME_TYPE, self._dtype.itemsize - 12, self.stats)
        self._tracker = SequenceTracker(self.stats, frame_period_us)

    @classmethod
    def from_config(
        cls, config: CodaConfig | Mapping[str, Any], *, stats: LinkStats | None = None
    ) -> CodaDecoder:
        """A decoder for a configuration (a :class:`CodaConfig` or its ``to_dict()``)."""
        config = as_config(config, CodaConfig)
        return cls(config.ids, config.mode, stats=stats, frame_period_us=1e9 / config.rate_mhz)

    def _empty(self) -> FrameBlock:
        return FrameBlock.empty(self.rows, 1, len(VALUES))

    def _decode(self, batch: FrameBatch) -> FrameBlock:
        if not len(batch):
            return self._empty()
        frames = np.ascontiguousarray(batch.frames).reshape(-1).view(self._dtype)
        arrival = batch.arrival_ns
        m = len(self.markers)
        ok = (
            (frames["mode"] == MODES[self.mode])
            & (frames["n_markers"] == m)
            & (frames["n_slots"] == m + SPARE_SLOTS)
            & (frames["n_items"] <= m + SPARE_SLOTS)
        )
        if not ok.all():
            if not self.config_mismatches:
                bad = frames[~ok][0]
                log.warning(
                    "CSX frames contradict the configuration (%d markers, %s): frame says "
                    "mode %d, %d markers, %d items; dropping such frames",
                    m, self.mode, bad["mode"], bad["n_markers"], bad["n_items"],
                )  # fmt: skip
            self.config_mismatches += int((~ok).sum())
            frames, arrival = frames[ok], arrival[ok]
            if not frames.shape[0]:
                return self._empty()
        keep, seq, ticks = self._tracker.update(frames["seq"], frames["frame_no"], frames["tick"])
        if not keep.all():
            frames, arrival, seq, ticks = frames[keep], arrival[keep], seq[keep], ticks[keep]
        data, flags = self._records(frames["records"], frames["n_items"])
        return FrameBlock(
            seq=seq,
            ticks=ticks,
            arrival_ns=np.asarray(arrival, dtype=np.int64),
            data=data,
            flags=flags,
            status=frames["status"].astype(np.uint16),
        )

    def _records(
        self, rec: npt.NDArray[Any], n_items: npt.NDArray[Any]
    ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.uint8]]:
        f, s = rec.shape
        m = len(self.markers)
        values = np.full((f, s, len(VALUES)), np.nan)
        used = np.arange(s)[None, :] < n_items[:, None]
        rflags = rec["flags"]
        values[..., 0] = rec["id"]
        if MODES[self.mode] & 1:
            valid = (rflags & F_3D_VALID) != 0
            values[..., 1:4] = np.where(valid[..., None], rec["xyz"] / 100.0, np.nan)
        if MODES[self.mode] & 2:
            values[..., 4:7] = counts_to_rad(rec["counts"])
            dt = rec["dt"]
            values[..., 7:10] = np.where(dt == NOT_SEEN, np.nan, dt.astype(np.float64))
        row = self._row_of_id[rec["id"]]
        clean = used & ((rflags & F_SUSPECT) == 0) & (row >= 0)
        # A second unflagged record of one ID in a frame: every copy is suspect.
        hits = np.zeros((f, m + 1), dtype=np.int64)
        fi = np.repeat(np.arange(f), s).reshape(f, s)
        np.add.at(hits, (fi[clean], row[clean]), 1)
        clean &= hits[fi, np.where(row >= 0, row, m)] == 1
        suspect = used & ~clean
        self.suspect_records += int(suspect.sum())
        out_row = np.where(clean, row, m + np.cumsum(suspect, axis=1) - 1)
        data = np.full((f, self.rows, 1, len(VALUES)), np.nan)
        flags = np.zeros((f, self.rows, 1), dtype=np.uint8)
        sel = used
        data[fi[sel], out_row[sel], 0, :] = values[sel]
        flags[fi[sel], out_row[sel], 0] = rflags[sel] | ROW_USED
        return data, flags


def decoder_from_metadata(meta: Mapping[str, Any]) -> CodaDecoder:
    """Rebuild the decoder of a recorded CSX stream.

    ``meta`` is :meth:`CodaDriver.metadata`, the stream's ``StreamSpec.to_dict()`` or the
    configuration's ``to_dict()`` (:func:`~spotlab.drivers.mcs1.metadata.recorded_config`,
    which raises ``ConfigurationError`` for another family's).
    """
    return CodaDecoder.from_config(recorded_config(meta, "coda", "CSX", ("markers", "mode")))
