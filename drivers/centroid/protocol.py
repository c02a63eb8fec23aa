"""Host side of the CEN bytes: hub frames to :class:`FrameBlock` (centroid.md §3-4).

:class:`CentroidDecoder` chains the variable-length MCS-1 frame decoder, a
numpy view of the fixed hub header of every frame, one pass over the camera
records and the MCS-1 sequence tracker; the same object decodes a live link and
a recording.

FrameBlock layout of a ``blobs2d`` stream (``C`` camera columns, ``B`` the most
blobs one camera sent in the block; ``B`` varies from block to block, use
:func:`spotlab.drivers.centroid.blobs.blobs_from_blocks` to join blocks):

* ``ticks`` (F,): the hub µs tick at each frame's trigger, unwrapped
  (``StreamSpec.tick_hz = 1e6``);
* ``data`` (F, 1 + B, C, 4): row 0 is the camera row, values
  ``(exposure, camera_frame, n_found, n_blobs)`` — the camera clock at the
  exposure mid-point (µs of *that camera's* clock), its frame counter, the blobs
  it found and those it sent; NaN for a camera not enabled or offline (then
  ``n_found`` and ``n_blobs`` are 0 and ``camera_frame`` its last). Rows
  ``1 .. B`` are blobs ``(x px, y px, area px, peak)``, NaN past ``n_blobs``;
* ``flags`` (F, 1 + B, C): row 0 the camera flags (``CAM_OVERFLOW``,
  ``CAM_OFFLINE``) plus :data:`RECORD_PRESENT` for an enabled camera's record;
  blob rows the blob flags (``BLOB_SATURATED``, ``BLOB_EDGE``, ``BLOB_MERGED``)
  plus :data:`BLOB_USED`;
* ``status`` (F,): the status word.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from spotlab.core.frames import FrameBlock
from spotlab.core.stats import LinkStats
from spotlab.drivers.centroid.config import CentroidConfig
from spotlab.drivers.centroid.framing import VariableFrameDecoder
from spotlab.drivers.mcs1.decoding import Mcs1StreamDecoder
from spotlab.drivers.mcs1.framing import FrameBatch
from spotlab.drivers.mcs1.metadata import as_config, recorded_config
from spotlab.drivers.mcs1.sequence import SequenceTracker
from spotlab.drivers.mcs1.version import VersionReply

log = logging.getLogger(__name__)

FRAME_TYPE = 0x05
FAMILY_CODE = "CEN"
TICK_HZ = 1_000_000
SUBPIXEL = 32.0
VALUES = ("x|exposure", "y|camera_frame", "area|n_found", "peak|n_blobs")
UNITS = ("px|tick", "px|count", "px|count", "grey|count")
CAM_OVERFLOW = 0x01
CAM_OFFLINE = 0x02
BLOB_SATURATED = 0x01
BLOB_EDGE = 0x02
BLOB_MERGED = 0x04
#: Added to a camera row's flags for an enabled camera's record.
RECORD_PRESENT = 0x80
#: Added to a blob row's flags for a blob sent.
BLOB_USED = 0x80
HUB_DTYPE = np.dtype(
    {
        "names": ["seq", "len", "frame_no", "tick", "status", "n_items", "mask", "max_blobs"],
        "formats": ["<u2", "<u2", "<u4", "<u4", "<u2", "<u2", "<u2", "<u2"],
        "offsets": [4, 6, 10, 14, 18, 20, 22, 24],
        "itemsize": 30,
    }
)
CAMERA_DTYPE = np.dtype(
    [("camera", "u1"), ("flags", "u1"), ("n_blobs", "<u2"), ("n_found", "<u2"),
     ("reserved", "<u2"), ("frame", "<u4"), ("exposure", "<u8")]
)  # fmt: skip
BLOB_DTYPE = np.dtype(
    [("x", "<u2"), ("y", "<u2"), ("area", "<u2"), ("peak", "u1"), ("flags", "u1")]
)
_HUB_END = 30  # header (10) + hub header (20)


@dataclass(frozen=True)
class CentroidVersion(VersionReply):
    """What a CEN hub says of itself in reply to ``VER:0`` (centroid.md §2)."""

    code = FAMILY_CODE
    form = "<cameras> <max blobs> <camera tick Hz>"

    firmware: str
    serial_number: str
    cameras: int
    max_blobs: int
    tick_hz: int
    text: str


#: Parse a ``VER:0`` reply text (``ProtocolError`` if it is not the family's).
parse_version = CentroidVersion.parse


class CentroidDecoder(Mcs1StreamDecoder):
    """Bytes of a CEN link in, :class:`FrameBlock` out (a ``StreamDecoder``).

    Parameters
    ----------
    config : CentroidConfig
        The configuration the frames must match (cameras, blob cap, rate).
    stats : LinkStats, optional
        Counters to update; a new one by default.

    Attributes
    ----------
    stats : LinkStats
        Frames, losses, duplicates, gaps, CRC errors, resyncs, bytes.
    malformed : int
        Frames dropped because their records contradict the configuration or
        do not fill the payload exactly.
    blobs : int
        Blobs decoded so far.
    overflow_frames : ndarray of int64, shape (C,)
        Per camera, frames flagged overflow (more blobs found than sent).
    offline_frames : ndarray of int64, shape (C,)
        Per camera, frames the camera did not deliver.
    camera_gaps : ndarray of int64, shape (C,)
        Per camera, stretches of offline frames.
    """

    def __init__(self, config: CentroidConfig, *, stats: LinkStats | None = None) -> None:
        self.config = config
        self.stats = stats if stats is not None else LinkStats()
        self.malformed = 0
        self.blobs = 0
        c = config.n_columns
        self.overflow_frames = np.zeros(c, dtype=np.int64)
        self.offline_frames = np.zeros(c, dtype=np.int64)
        self.camera_gaps = np.zeros(c, dtype=np.int64)
        self._offline_now = np.zeros(c, dtype=bool)
        self._frames = VariableFrameDecoder(
            FRAME_TYPE, config.min_payload, config.max_payload, self.stats
        )
        self._tracker = SequenceTracker(self.stats, 1e9 / config.rate_mhz)
        self._cameras = np.asarray(config.cameras, dtype=np.int64)

    @classmethod
    def from_config(
        cls, config: CentroidConfig | Mapping[str, Any], *, stats: LinkStats | None = None
    ) -> CentroidDecoder:
        """A decoder for a configuration (a :class:`CentroidConfig` or its ``to_dict()``)."""
        config = as_config(config, CentroidConfig)
        return cls(config, stats=stats)

    def summary(self) -> dict[str, Any]:
        """Blob counts for ``spotlab info``: blobs per frame, overflows and gaps per camera."""
        frames = self.stats.frames
        return {
            "blobs": self.blobs,
            "blobs_per_frame": self.blobs / frames if frames else 0.0,
            "overflow_frames": self.overflow_frames.tolist(),
            "offline_frames": self.offline_frames.tolist(),
            "camera_gaps": self.camera_gaps.tolist(),
            "malformed_frames": self.malformed,
        }

    def _empty(self) -> FrameBlock:
        return FrameBlock.empty(1, self.config.n_columns, len(VALUES))

    def _decode(self, batch: FrameBatch) -> FrameBlock:
        if not len(batch):
            return self._empty()
        rows = batch.frames
        hub = np.ascontiguousarray(rows[:, :_HUB_END]).reshape(-1).view(HUB_DTYPE)
        cfg = self.config
        ok = (
            (hub["mask"] == cfg.camera_mask)
            & (hub["max_blobs"] == cfg.max_blobs)
            & (hub["n_items"] == cfg.n_enabled)
        )
        records = [
            self._records(rows[k], int(hub["len"][k])) if ok[k] else None for k in range(len(rows))
        ]
        good = np.array([r is not None for r in records])
        if not good.all():
            self.malformed += int((~good).sum())
            log.warning("CEN: %d frames contradict the configuration; dropped", int((~good).sum()))
            hub, arrival = hub[good], batch.arrival_ns[good]
            records = [r for r in records if r is not None]
            if not records:
                return self._empty()
        else:
            arrival = batch.arrival_ns
        keep, seq, ticks = self._tracker.update(hub["seq"], hub["frame_no"], hub["tick"])
        if not keep.any():
            return self._empty()
        if not keep.all():
            hub, arrival, seq, ticks = hub[keep], arrival[keep], seq[keep], ticks[keep]
            records = [r for r, k in zip(records, keep, strict=True) if k]
        data, flags = self._fill([r for r in records if r is not None])
        return FrameBlock(
            seq=seq,
            ticks=ticks,
            arrival_ns=np.asarray(arrival, dtype=np.int64),
            data=data,
            flags=flags,
            status=hub["status"].astype(np.uint16),
        )

    def _records(
        self, row: npt.NDArray[np.uint8], length: int
    ) -> tuple[npt.NDArray[Any], list[npt.NDArray[Any]]] | None:
        """Camera headers and blob arrays of one frame, or None when malformed."""
        end = 10 + length
        pos = _HUB_END
        heads = []
        blobs = []
        for _ in range(self.config.n_enabled):
            if pos + CAMERA_DTYPE.itemsize > end:
                return None
            head = row[pos : pos + CAMERA_DTYPE.itemsize].view(CAMERA_DTYPE)[0]
            n = int(head["n_blobs"])
            pos += CAMERA_DTYPE.itemsize
            if n > self.config.max_blobs or pos + 8 * n > end:
                return None
            heads.append(head)
            blobs.append(row[pos : pos + 8 * n].view(BLOB_DTYPE))
            pos += 8 * n
        if pos != end:
            return None
        cams = np.array([int(h["camera"]) for h in heads], dtype=np.int64)
        if not np.array_equal(cams, self._cameras):
            return None
        return np.array(heads, dtype=CAMERA_DTYPE), blobs

    def _fill(
        self, records: list[tuple[npt.NDArray[Any], list[npt.NDArray[Any]]]]
    ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.uint8]]:
        f, c = len(records), self.config.n_columns
        b = max((len(x) for _, bl in records for x in bl), default=0)
        data = np.full((f, 1 + b, c, len(VALUES)), np.nan)
        flags = np.zeros((f, 1 + b, c), dtype=np.uint8)
        cams = self._cameras
        heads = np.stack([h for h, _ in records])  # (F, n_enabled)
        offline = (heads["flags"] & CAM_OFFLINE) != 0
        cam_row = data[:, 0]
        cam_row[:, cams, 0] = np.where(offline, np.nan, heads["exposure"].astype(np.float64))
        cam_row[:, cams, 1] = heads["frame"]
        cam_row[:, cams, 2] = heads["n_found"]
        cam_row[:, cams, 3] = heads["n_blobs"]
        flags[:, 0, cams] = heads["flags"] | RECORD_PRESENT
        for k, (_, blob_list) in enumerate(records):
            for j, bl in enumerate(blob_list):
                n = len(bl)
                if not n:
                    continue
                col = data[k, 1 : 1 + n, cams[j]]
                col[:, 0] = bl["x"] / SUBPIXEL
                col[:, 1] = bl["y"] / SUBPIXEL
                col[:, 2] = bl["area"]
                col[:, 3] = bl["peak"]
                flags[k, 1 : 1 + n, cams[j]] = bl["flags"] | BLOB_USED
        self.blobs += int(heads["n_blobs"].sum())
        self.overflow_frames[cams] += ((heads["flags"] & CAM_OVERFLOW) != 0).sum(axis=0)
        self.offline_frames[cams] += offline.sum(axis=0)
        was = np.vstack([self._offline_now[cams][None, :], offline[:-1]])
        self.camera_gaps[cams] += (offline & ~was).sum(axis=0)
        self._offline_now[cams] = offline[-1]
        return data, flags


def decoder_from_metadata(meta: Mapping[str, Any]) -> CentroidDecoder:
    """Rebuild the decoder of a recorded CEN stream.

    ``meta`` is :meth:`CentroidDriver.metadata`, the stream's ``StreamSpec.to_dict()`` or the
    configuration's ``to_dict()`` (:func:`~spotlab.drivers.mcs1.metadata.recorded_config`,
    which raises ``ConfigurationError`` for another family's).
    """
    return CentroidDecoder.from_config(recorded_config(meta, "centroid", "CEN", ("camera_mask",)))
