"""The seam between the OAK driver and depthai: the few calls the driver makes of a board.

Everything behind the seam (centroiding, frame matching, timestamps, journal
records) is tested with a fake board that replays rendered frames
(``spotlab.simulators.oak.FakeOakDevice``); the depthai side
(:class:`~spotlab.drivers.oak.depthai_camera.DepthaiCamera`) stays thin and is
tested on hardware by the conformance suite (``pytest --hw oak=MXID``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, Protocol

import numpy as np
import numpy.typing as npt

from spotlab.core.errors import DeviceError

#: FSIN roles: ``master`` drives the frame-sync line, ``slave`` waits for it, ``off``
#: runs free (one board without a sync cable).
SyncRole = Literal["master", "slave", "off"]
UDEV_RULE = "60-spotlab.rules with 61-spotlab-uaccess.rules (spotlab udev install)"


class UsbPermissionError(DeviceError, PermissionError):
    """The OAK is on the bus but this user may not open it: the udev rule is missing."""


@dataclass(frozen=True)
class CameraSettings:
    """How every mono camera of a board is run.

    Attributes
    ----------
    size : (int, int)
        Image ``(width, height)`` (px), 1280x800 for the OV9282 at full resolution.
    fps : float
        Frame rate (Hz); with FSIN it must equal the master's exactly.
    exposure_us : int
        Manual exposure time (µs); short, so markers are sharp and the room dark.
    iso : int
        Sensor sensitivity (ISO, 100-1600).
    sync : {"master", "slave", "off"}
        The board's FSIN role.
    """

    size: tuple[int, int] = (1280, 800)
    fps: float = 120.0
    exposure_us: int = 500
    iso: int = 400
    sync: SyncRole = "off"


class OakFrameLike(Protocol):
    """One image of one camera, as the seam hands it over.

    Attributes
    ----------
    socket : str
        Camera socket on the board (``"CAM_B"``).
    seq : int
        The camera's frame counter (depthai ``getSequenceNum``).
    image : ndarray of uint8, shape (H, W)
        Grey levels.
    host_ns : int
        Exposure mid-point on the host's monotonic clock (ns): depthai's
        ``getTimestamp(CameraExposureOffset.MIDDLE)``, which depthai keeps synced to
        ``std::chrono::steady_clock`` (CLOCK_MONOTONIC on Linux, as
        ``time.monotonic_ns``).
    device_ns : int
        Exposure mid-point on the board's own monotonic clock (ns):
        ``getTimestampDevice(CameraExposureOffset.MIDDLE)``.
    exposure_us : int
        Exposure time the sensor used (µs): ``getExposureTime``.
    """

    @property
    def socket(self) -> str: ...
    @property
    def seq(self) -> int: ...
    @property
    def image(self) -> npt.NDArray[np.uint8]: ...
    @property
    def host_ns(self) -> int: ...
    @property
    def device_ns(self) -> int: ...
    @property
    def exposure_us(self) -> int: ...


class OakCamera(Protocol):
    """One OAK board (one MxId) with its mono cameras, behind the seam.

    Attributes
    ----------
    mxid : str
        The board's device id.
    sockets : tuple of str
        Its mono camera sockets, in the order the driver numbers them.
    """

    mxid: str
    sockets: tuple[str, ...]

    def open(self, settings: CameraSettings) -> None:
        """Find the board, build the pipeline for ``settings``; raise DeviceNotFound or
        UsbPermissionError with a message saying what was searched and what to do."""

    def start(self) -> None:
        """Start streaming."""

    def frames(self, timeout: float) -> list[OakFrameLike]:
        """Frames that arrived, waiting up to ``timeout`` s for the first."""
        ...

    def close(self) -> None:
        """Stop and release the board; safe to call twice."""
