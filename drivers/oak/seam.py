"""The seam between the OAK driver and depthai: the few calls the driver makes of a board.

Everything behind the seam (centroiding, frame matching, timestamps, journal
records) is tested with a fake board that replays rendered frames
(``spotlab.simulators.oak.FakeOakDevice``); the depthai side
(:class:`~spotlab.drivers.oak.depthai_camera.DepthaiCamera`) stays thin and is
tested on hardware by the conformance suite (``pytest --hw oak=MXID``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal, Protocol

import numpy as np
import numpy.typing as npt

from spotlab.core.errors import ConfigurationError, DeviceError

#: FSIN roles: ``master`` drives the frame-sync line, ``slave`` waits for it, ``off``
#: runs free (one board without a sync cable).
SyncRole = Literal["master", "slave", "off"]
UDEV_RULE = "60-spotlab.rules with 61-spotlab-uaccess.rules (spotlab udev install)"
#: Exposure range accepted (µs): the OV9282 runs down to a few µs; a frame at 1 Hz is
#: the longest exposure that makes sense for a mocap camera.
EXPOSURE_US = (1, 1_000_000)
#: ISO range of depthai's ``setManualExposure`` ("usual range 100..1600").
ISO = (100, 1600)
#: Frame rates accepted (Hz); the OV9282 reaches 120 Hz at 1280x800, more when cropped.
FPS = (1.0, 480.0)


class UsbPermissionError(DeviceError, PermissionError):
    """The OAK is on the bus but this user may not open it: the udev rule is missing."""


class OakInUseError(DeviceError):
    """The OAK is booted by another process (another depthai program holds it)."""


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
    allow_unsynced : bool
        With ``sync`` master or slave, the first image of every camera must say it was
        taken under FSIN (depthai ``ImgFrame.getFsync()`` not ``NONE``), else the board
        refuses to stream; True accepts free-running images.

    Raises
    ------
    ConfigurationError
        A field of the wrong type (a float exposure, which depthai would read as
        seconds; a float ISO) or out of range.
    """

    size: tuple[int, int] = (1280, 800)
    fps: float = 120.0
    exposure_us: int = 500
    iso: int = 400
    sync: SyncRole = "off"
    allow_unsynced: bool = False

    def __post_init__(self) -> None:
        for name, (lo, hi) in (("exposure_us", EXPOSURE_US), ("iso", ISO)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int):
                raise ConfigurationError(
                    f"CameraSettings.{name} must be an int, not {type(value).__name__} "
                    f"{value!r} (depthai reads a float exposure as seconds)"
                )
            if not lo <= value <= hi:
                raise ConfigurationError(f"CameraSettings.{name}={value} is outside {lo}-{hi}")
        if isinstance(self.fps, bool) or not isinstance(self.fps, int | float):
            raise ConfigurationError(f"CameraSettings.fps must be a number, not {self.fps!r}")
        if not (math.isfinite(self.fps) and FPS[0] <= self.fps <= FPS[1]):
            raise ConfigurationError(
                f"CameraSettings.fps={self.fps} is outside {FPS[0]}-{FPS[1]} Hz"
            )
        if self.exposure_us > 1e6 / self.fps:
            raise ConfigurationError(
                f"CameraSettings.exposure_us={self.exposure_us} is longer than a frame at "
                f"{self.fps} Hz ({1e6 / self.fps:.0f} µs)"
            )
        size = tuple(self.size)
        if len(size) != 2 or not all(isinstance(v, int) and v > 0 for v in size):
            raise ConfigurationError(
                f"CameraSettings.size must be (width, height) in px, not {self.size!r}"
            )
        if self.sync not in ("master", "slave", "off"):
            raise ConfigurationError(
                f"CameraSettings.sync must be master, slave or off, not {self.sync!r}"
            )


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
    info : dict of str to str
        What the board reported: ``usb_speed`` and ``sensor.<socket>`` after
        :meth:`start`, ``format.<socket>`` and ``fsync.<socket>`` once that camera's
        first image arrived (docs/oak.md).
    """

    mxid: str
    sockets: tuple[str, ...]
    info: dict[str, str]

    def open(self, settings: CameraSettings) -> None:
        """Find the board, build the pipeline for ``settings``; raise DeviceNotFound or
        UsbPermissionError with a message saying what was searched and what to do."""

    def start(self) -> None:
        """Start streaming (again after :meth:`stop`); fill ``info`` (USB speed, sensors)."""

    def stop(self) -> None:
        """Stop streaming; :meth:`start` may follow."""

    def frames(self, timeout: float) -> list[OakFrameLike]:
        """Frames that arrived on any camera, waiting up to ``timeout`` s for the first;
        DeviceDisconnected when the board went away."""
        ...

    def close(self) -> None:
        """Stop and release the board; safe to call twice."""
