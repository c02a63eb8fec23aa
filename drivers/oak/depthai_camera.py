"""The depthai (v3) side of the seam: one OAK board, its mono cameras, FSIN, timestamps.

Thin on purpose: everything here is a depthai call; what the driver does with the
frames is tested behind the seam with a fake board. depthai is imported on first
use, so spotlab runs without it (``pip install spotlab[oak]``).
"""

from __future__ import annotations

import importlib
from typing import Any

import numpy as np

from spotlab.core.errors import ConfigurationError, DeviceError, DeviceNotFound
from spotlab.drivers.oak.seam import UDEV_RULE, CameraSettings, OakFrameLike, UsbPermissionError
from spotlab.drivers.oak.simple_frame import OakFrame

#: Mono sockets of the OAK-D family (OV9282 left and right).
MONO_SOCKETS = ("CAM_B", "CAM_C")


def depthai_module() -> Any:
    """depthai, imported on first use, with a clear error when it is missing."""
    try:
        return importlib.import_module("depthai")
    except ImportError as exc:
        raise ConfigurationError(
            "the OAK driver needs depthai 3: pip install 'spotlab[oak]'"
        ) from exc


def find_devices() -> list[tuple[str, str, str]]:
    """OAK boards on this machine: ``(mxid, state, status)`` of each.

    ``getAllAvailableDevices`` answers in about 0.5 s with or without hardware (it
    does not boot anything), unlike ``dai.Device()`` which searches ~11 s.
    """
    dai = depthai_module()
    return [
        (info.deviceId, info.state.name, info.status.name)
        for info in dai.Device.getAllAvailableDevices()
    ]


def _check_found(mxid: str, found: list[tuple[str, str, str]]) -> None:
    match = [f for f in found if f[0] == mxid]
    if not match:
        seen = ", ".join(f[0] for f in found) or "none"
        raise DeviceNotFound(
            f"no OAK with MxId {mxid} found (searched USB and the network with depthai "
            f"getAllAvailableDevices; boards seen: {seen}). Is it plugged in and powered? "
            f"A board on USB that lsusb lists as 03e7:2485 or 03e7:f63b but depthai cannot "
            f"see needs the udev rule: {UDEV_RULE}; see docs/oak.md"
        )
    if match[0][2] == "X_LINK_INSUFFICIENT_PERMISSIONS":
        raise UsbPermissionError(
            f"the OAK {mxid} is on the bus but this user may not open it "
            f"(X_LINK_INSUFFICIENT_PERMISSIONS): install the udev rule {UDEV_RULE}, then "
            "unplug and replug the board; see docs/udev.md"
        )


class DepthaiCamera:
    """One OAK board through depthai v3.

    Parameters
    ----------
    mxid : str
        The board's device id (``spotlab devices`` or depthai's device list).
    sockets : tuple of str, optional
        Mono camera sockets to run (default the OAK-D pair ``CAM_B``, ``CAM_C``).
    """

    def __init__(self, mxid: str, sockets: tuple[str, ...] = MONO_SOCKETS) -> None:
        self.mxid = mxid
        self.sockets = tuple(sockets)
        self._pipeline: Any = None
        self._queues: dict[str, Any] = {}

    def open(self, settings: CameraSettings) -> None:
        """Find the board and build the pipeline: GRAY8 outputs, manual exposure, FSIN."""
        dai = depthai_module()
        _check_found(self.mxid, find_devices())
        try:
            device = dai.Device(dai.DeviceInfo(self.mxid))
        except RuntimeError as exc:
            if "PERMISSION" in str(exc).upper():
                raise UsbPermissionError(
                    f"OAK {self.mxid}: {exc}; install the udev rule {UDEV_RULE}"
                ) from exc
            raise DeviceNotFound(f"OAK {self.mxid} could not be opened: {exc}") from exc
        mode = {
            "master": dai.CameraControl.FrameSyncMode.OUTPUT,
            "slave": dai.CameraControl.FrameSyncMode.INPUT,
            "off": dai.CameraControl.FrameSyncMode.OFF,
        }[settings.sync]
        pipeline = dai.Pipeline(device)
        for socket in self.sockets:
            cam = pipeline.create(dai.node.Camera).build(
                getattr(dai.CameraBoardSocket, socket), sensorFps=settings.fps
            )
            cam.initialControl.setManualExposure(settings.exposure_us, settings.iso)
            cam.initialControl.setFrameSyncMode(mode)
            out = cam.requestOutput(settings.size, dai.ImgFrame.Type.GRAY8, fps=settings.fps)
            self._queues[socket] = out.createOutputQueue(maxSize=8, blocking=False)
        self._pipeline = pipeline

    def start(self) -> None:
        """Start the pipeline on the board."""
        if self._pipeline is None:
            raise DeviceError(f"OAK {self.mxid}: open() before start()")
        self._pipeline.start()

    def frames(self, timeout: float) -> list[OakFrameLike]:
        """Frames of every socket that arrived, waiting up to ``timeout`` s for one."""
        import datetime

        dai = depthai_module()
        middle = dai.CameraExposureOffset.MIDDLE
        out: list[OakFrameLike] = []
        for i, (socket, queue) in enumerate(self._queues.items()):
            msgs = queue.tryGetAll()
            if not msgs and i == 0 and timeout > 0:
                msg = queue.get(datetime.timedelta(seconds=timeout))
                msgs = [] if msg is None else [msg]
            for m in msgs:
                out.append(
                    OakFrame(
                        socket=socket,
                        seq=int(m.getSequenceNum()),
                        image=np.asarray(m.getFrame(), dtype=np.uint8),
                        host_ns=_ns(m.getTimestamp(middle)),
                        device_ns=_ns(m.getTimestampDevice(middle)),
                        exposure_us=_ns(m.getExposureTime()) // 1000,
                    )
                )
        return out

    def close(self) -> None:
        """Stop the pipeline and release the board (safe twice)."""
        pipeline, self._pipeline = self._pipeline, None
        self._queues = {}
        if pipeline is not None:
            pipeline.stop()


def _ns(delta: Any) -> int:
    return (delta.days * 86_400 + delta.seconds) * 1_000_000_000 + delta.microseconds * 1000
