"""Device side of the CEN bytes: video-centroid hub frames (docs/protocols/centroid.md).

Written from the spec, not from the driver's codec. Pure functions of their
arguments, so the golden byte vectors of centroid.md are produced and checked
here directly. All multi-byte fields are little-endian; checksums are
CRC-16/CCITT-FALSE.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from spotlab.core.crc import crc16
from spotlab.simulators.wire import BAUD_RATES, PROTOCOL_VERSION, SYNC

FRAME_CEN = 0x05
FAMILY_CODE = "CEN"
#: Camera clocks count µs.
CAMERA_TICK_HZ = 1_000_000
#: Blob coordinates are sent in 1/32 px.
SUBPIXEL = 32
MAX_CAMERAS = 16
MAX_BLOBS = 1024
#: Longest CEN payload (the 16-bit ``len`` field).
MAX_PAYLOAD = 65_535
HUB_HEADER_BYTES = 20
CAMERA_HEADER_BYTES = 20
BLOB_BYTES = 8
FRAME_OVERHEAD = 12
#: ``COMM:<c>`` codes of the CEN hub: MCS-1's, and 10 (6 Mbaud), 11 (12 Mbaud), 12 (24 Mbaud).
CEN_BAUD_RATES: dict[int, int] = {**BAUD_RATES, 10: 6_000_000, 11: 12_000_000, 12: 24_000_000}

# Camera record flags (centroid.md §4).
CAM_OVERFLOW = 0x01
CAM_OFFLINE = 0x02
# Blob flags (centroid.md §4).
BLOB_SATURATED = 0x01
BLOB_EDGE = 0x02
BLOB_MERGED = 0x04

_HEADER = struct.Struct("<2sBBHH")
_HUB = struct.Struct("<IIHHHHHBB")
_CAMERA = struct.Struct("<BBHHHIQ")
BLOB_DTYPE = np.dtype(
    [("x", "<u2"), ("y", "<u2"), ("area", "<u2"), ("peak", "u1"), ("flags", "u1")]
)


@dataclass
class CameraRecord:
    """One camera's frame as the hub sends it.

    Attributes
    ----------
    camera : int
        Camera index, 0-15.
    flags : int
        ``CAM_OVERFLOW``, ``CAM_OFFLINE``.
    n_found : int
        Blobs the camera found (more than sent when it overflowed).
    camera_frame : int
        The camera's frame counter.
    exposure_tick : int
        The camera clock (µs) at the exposure mid-point.
    blobs : ndarray of BLOB_DTYPE, shape (n,)
        The blobs sent, at most the cap.
    """

    camera: int
    flags: int
    n_found: int
    camera_frame: int
    exposure_tick: int
    blobs: npt.NDArray[np.void]


def quantise_blobs(
    uv: npt.ArrayLike, area: npt.ArrayLike, peak: npt.ArrayLike, flags: npt.ArrayLike
) -> npt.NDArray[np.void]:
    """Blob records from centroids (N, 2) px, areas (px), peaks (0-255) and flag bytes.

    Coordinates are rounded to 1/32 px and clipped to 0 .. 2047.97 px; areas
    saturate at 65535 px.
    """
    uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
    out = np.zeros(uv.shape[0], dtype=BLOB_DTYPE)
    q = np.clip(np.rint(uv * SUBPIXEL), 0, 0xFFFF).astype(np.uint16)
    out["x"], out["y"] = q[:, 0], q[:, 1]
    out["area"] = np.clip(np.rint(np.asarray(area, dtype=np.float64)), 1, 0xFFFF)
    out["peak"] = np.clip(np.rint(np.asarray(peak, dtype=np.float64)), 0, 255)
    out["flags"] = np.asarray(flags, dtype=np.uint8)
    return out


def cen_payload(
    frame_no: int,
    tick_us: int,
    status: int,
    camera_mask: int,
    max_blobs: int,
    exposure_us: int,
    threshold: int,
    records: list[CameraRecord],
) -> bytes:
    """The payload of a CEN data frame (centroid.md §3-4).

    Raises
    ------
    ValueError
        If a record holds more blobs than ``max_blobs`` or the payload exceeds 65535 bytes.
    """
    parts = [
        _HUB.pack(
            frame_no & 0xFFFFFFFF, tick_us & 0xFFFFFFFF, status & 0xFFFF, len(records),
            camera_mask & 0xFFFF, max_blobs, exposure_us, threshold, 0,
        )
    ]  # fmt: skip
    for r in records:
        if r.blobs.shape[0] > max_blobs:
            raise ValueError(f"camera {r.camera}: {r.blobs.shape[0]} blobs > cap {max_blobs}")
        parts.append(
            _CAMERA.pack(
                r.camera, r.flags, r.blobs.shape[0], min(r.n_found, 0xFFFF), 0,
                r.camera_frame & 0xFFFFFFFF, r.exposure_tick & 0xFFFFFFFFFFFFFFFF,
            )
        )  # fmt: skip
        parts.append(np.ascontiguousarray(r.blobs, dtype=BLOB_DTYPE).tobytes())
    payload = b"".join(parts)
    if len(payload) > MAX_PAYLOAD:
        raise ValueError(f"CEN payload of {len(payload)} bytes exceeds {MAX_PAYLOAD}")
    return payload


def cen_frame(seq: int, payload: bytes, flags: int = PROTOCOL_VERSION << 4) -> bytes:
    """A whole CEN data frame (MCS-1 §4 framing, payload up to 65535 bytes)."""
    head = _HEADER.pack(SYNC, FRAME_CEN, flags, seq & 0xFFFF, len(payload))
    return b"".join(
        (head, crc16(head).to_bytes(2, "little"), payload, crc16(payload).to_bytes(2, "little"))
    )


def cen_frame_length(n_cameras: int, n_blobs: int) -> int:
    """Bytes of a whole data frame with ``n_cameras`` records and ``n_blobs`` blobs in all."""
    return (
        FRAME_OVERHEAD + HUB_HEADER_BYTES + CAMERA_HEADER_BYTES * n_cameras + BLOB_BYTES * n_blobs
    )
