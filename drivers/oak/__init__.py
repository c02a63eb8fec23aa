"""Luxonis OAK cameras through depthai (v3) as video-centroid mocap cameras.

The driver (:class:`OakDriver`) talks to boards through a seam
(:class:`OakCamera`): :class:`DepthaiCamera` on hardware, a fake board in tests.
depthai is imported only when a real board is opened.
"""

from spotlab.drivers.oak.driver import OakDriver
from spotlab.drivers.oak.record import (
    FLAG_FLOODED,
    FLAG_OFFLINE,
    MAGIC,
    CameraShot,
    OakRecordDecoder,
    decoder_from_metadata,
    encode_frame,
)
from spotlab.drivers.oak.seam import (
    CameraSettings,
    OakCamera,
    OakFrameLike,
    OakInUseError,
    SyncRole,
    UsbPermissionError,
)
from spotlab.drivers.oak.simple_frame import OakFrame

__all__ = [
    "FLAG_FLOODED",
    "FLAG_OFFLINE",
    "MAGIC",
    "CameraSettings",
    "CameraShot",
    "OakCamera",
    "OakDriver",
    "OakFrame",
    "OakFrameLike",
    "OakInUseError",
    "OakRecordDecoder",
    "SyncRole",
    "UsbPermissionError",
    "decoder_from_metadata",
    "encode_frame",
]
