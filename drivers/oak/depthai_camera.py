"""The depthai (v3) side of the seam: one OAK board, its mono cameras, FSIN, timestamps.

Thin on purpose: everything here is a depthai call; what the driver does with the
frames is tested behind the seam with a fake board. depthai is imported on first
use, so spotlab runs without it (``pip install spotlab[oak]``). Tests hand in a
stand-in module (``spotlab.simulators.oak_depthai.FakeDepthai``) built on real
depthai queues, frames, controls and a host-only pipeline.
"""

from __future__ import annotations

import datetime
import importlib
import os
from typing import Any

import numpy as np

from spotlab.core.errors import ConfigurationError, DeviceDisconnected, DeviceError, DeviceNotFound
from spotlab.drivers.oak.seam import (
    UDEV_RULE,
    CameraSettings,
    OakFrameLike,
    OakInUseError,
    SyncRole,
    UsbPermissionError,
)
from spotlab.drivers.oak.simple_frame import OakFrame

#: Mono sockets of the OAK-D family (OV9282 left and right).
MONO_SOCKETS = ("CAM_B", "CAM_C")
#: Images a camera's host queue holds before the oldest is dropped.
QUEUE_SIZE = 8
PERMISSION = "X_LINK_INSUFFICIENT_PERMISSIONS"
#: XLink state of a board another process has booted and holds.
HELD = "X_LINK_BOOTED"


def depthai_module() -> Any:
    """depthai, imported on first use, with a clear error when it is missing."""
    # depthai's own logger prints warnings (such as "USB protocol not available")
    # on the user's terminal at import; errors only unless DEPTHAI_LEVEL says otherwise.
    os.environ.setdefault("DEPTHAI_LEVEL", "error")
    try:
        return importlib.import_module("depthai")
    except ImportError as exc:
        raise ConfigurationError(
            "the OAK driver needs depthai 3: pip install 'spotlab[oak]'"
        ) from exc


def find_devices(dai: Any = None) -> list[tuple[str, str, str, str]]:
    """OAK boards on this machine: ``(mxid, name, state, status)`` of each.

    Asks XLink for every connected board, the ones this user may not open included
    (``XLinkConnection.getAllConnectedDevices(X_LINK_ANY_STATE, skipInvalidDevices=
    False)``): ``Device.getAllAvailableDevices`` leaves those out, and boards booted by
    another process too. A board without permission has an empty MxId (XLink cannot
    read it) and its USB path as ``name``. Answers in about 0.5 s with or without
    hardware (measured with depthai 3.12); ``dai.Device()`` would search ~11 s.
    """
    dai = dai or depthai_module()
    found = dai.XLinkConnection.getAllConnectedDevices(dai.XLinkDeviceState.X_LINK_ANY_STATE, False)
    return [(i.deviceId, i.name, i.state.name, i.status.name) for i in found]


def _check_found(mxid: str, found: list[tuple[str, str, str, str]]) -> None:
    match = [f for f in found if f[0] == mxid]
    denied = any(f[3] == PERMISSION for f in found)
    if (match and match[0][3] == PERMISSION) or (not match and denied):
        paths = ", ".join(f"USB {f[1]}" for f in found if f[3] == PERMISSION)
        raise UsbPermissionError(
            f"OAK {mxid}: a board is on the bus ({paths}) but this user may not open it "
            f"(depthai status {PERMISSION}, so not even its MxId can be read): install the "
            f"udev rule with `spotlab udev install` ({UDEV_RULE}), then unplug and replug "
            "the board; see docs/udev.md"
        )
    if not match:
        seen = ", ".join(f"{f[0] or '?'} ({f[2]})" for f in found) or "none"
        raise DeviceNotFound(
            f"no OAK with MxId {mxid} found (searched USB and the network with depthai "
            f"XLinkConnection.getAllConnectedDevices; boards seen: {seen}). Is it plugged "
            "in and powered? A board that lsusb lists as 03e7:2485 or 03e7:f63b but depthai "
            f"cannot see needs the udev rule: {UDEV_RULE}; see docs/oak.md"
        )
    if match[0][2] == HELD:
        _in_use(mxid, match[0][2])


def _in_use(mxid: str, why: str) -> None:
    raise OakInUseError(
        f"OAK {mxid} is in use by another process ({why}): close the other depthai "
        "program (another spotlab session, a viewer) or unplug and replug the board"
    )


def fsync_modes(sync: SyncRole, sockets: tuple[str, ...]) -> dict[str, str]:
    """depthai ``CameraControl.FrameSyncMode`` name of each socket for a board role.

    A master drives FSIN from its first socket (``OUTPUT``) and its other sensors
    follow the line they share with it (``INPUT``), as Luxonis documents for the
    OAK-D mono pair; a slave's sensors all follow (``INPUT``); ``off`` sets ``OFF``
    explicitly (depthai 3.12 would otherwise leave ``AUTO``).
    """
    if sync == "master":
        return {s: "OUTPUT" if i == 0 else "INPUT" for i, s in enumerate(sockets)}
    return {s: "INPUT" if sync == "slave" else "OFF" for s in sockets}


class DepthaiCamera:
    """One OAK board through depthai v3.

    Parameters
    ----------
    mxid : str
        The board's device id (``spotlab devices`` or depthai's device list).
    sockets : tuple of str, optional
        Mono camera sockets to run (default the OAK-D pair ``CAM_B``, ``CAM_C``).
    dai : module, optional
        The depthai module (default: imported on first use); tests pass a fake.

    Attributes
    ----------
    info : dict of str to str
        What the board reported: ``usb_speed`` and ``sensor.<socket>`` at start,
        ``format.<socket>`` (type and size of the first image) and ``fsync.<socket>``
        (its ``getFsync()``) once frames arrive.
    """

    def __init__(
        self, mxid: str, sockets: tuple[str, ...] = MONO_SOCKETS, *, dai: Any = None
    ) -> None:
        self.mxid = mxid
        self.sockets = tuple(sockets)
        self.info: dict[str, str] = {}
        self._dai = dai
        self._settings: CameraSettings | None = None
        self._device: Any = None
        self._pipeline: Any = None
        self._queues: dict[str, Any] = {}
        self._checked: set[str] = set()

    @property
    def dai(self) -> Any:
        """The depthai module in use."""
        if self._dai is None:
            self._dai = depthai_module()
        return self._dai

    def open(self, settings: CameraSettings) -> None:
        """Find the board and build the pipeline: GRAY8 outputs, manual exposure, FSIN.

        Raises
        ------
        UsbPermissionError, OakInUseError, DeviceNotFound
            The board cannot be opened (the message says why and what to do).
        DeviceError
            The pipeline could not be built; the board is released before it is raised.
        """
        dai = self.dai
        _check_found(self.mxid, find_devices(dai))
        try:
            device = dai.Device(dai.DeviceInfo(self.mxid))
        except RuntimeError as exc:
            text = str(exc)
            if "PERMISSION" in text.upper():
                raise UsbPermissionError(
                    f"OAK {self.mxid}: {exc}; install the udev rule with `spotlab udev "
                    f"install` ({UDEV_RULE})"
                ) from exc
            if "IN_USE" in text.upper() or "used by another" in text:
                _in_use(self.mxid, text)
            raise DeviceNotFound(f"OAK {self.mxid} could not be opened: {exc}") from exc
        try:
            self._build(dai, device, settings)
        except Exception as exc:
            self._queues = {}
            self._pipeline = None
            device.close()
            raise DeviceError(
                f"OAK {self.mxid}: the depthai pipeline could not be built ({exc}); the "
                "board was released"
            ) from exc
        self._device = device
        self._settings = settings
        self._checked = set()

    def _build(self, dai: Any, device: Any, settings: CameraSettings) -> None:
        modes = fsync_modes(settings.sync, self.sockets)
        pipeline = dai.Pipeline(device)
        for socket in self.sockets:
            cam = pipeline.create(dai.node.Camera).build(
                getattr(dai.CameraBoardSocket, socket), sensorFps=float(settings.fps)
            )
            control = cam.initialControl
            control.setManualExposure(int(settings.exposure_us), int(settings.iso))
            control.setFrameSyncMode(getattr(dai.CameraControl.FrameSyncMode, modes[socket]))
            out = cam.requestOutput(
                tuple(settings.size), dai.ImgFrame.Type.GRAY8, fps=float(settings.fps)
            )
            self._queues[socket] = out.createOutputQueue(maxSize=QUEUE_SIZE, blocking=False)
        self._pipeline = pipeline

    def start(self) -> None:
        """Start the pipeline (after :meth:`stop`, rebuild it first); report the board."""
        if self._pipeline is None:
            if self._settings is None:
                raise DeviceError(f"OAK {self.mxid}: open() before start()")
            self.open(self._settings)
        try:
            self._pipeline.start()
        except RuntimeError as exc:
            raise DeviceError(f"OAK {self.mxid}: the pipeline did not start: {exc}") from exc
        self.info = {"usb_speed": self._device.getUsbSpeed().name}
        for socket, name in self._device.getCameraSensorNames().items():
            if socket.name in self.sockets:
                self.info[f"sensor.{socket.name}"] = str(name)

    def frames(self, timeout: float) -> list[OakFrameLike]:
        """Frames of every socket that arrived, waiting up to ``timeout`` s for one on any.

        Raises
        ------
        DeviceDisconnected
            A queue was closed under the driver (board unplugged or reset), or depthai
            raised a RuntimeError reading it (XLink communication lost).
        DeviceError
            With FSIN asked for, a camera's first image says it was not synchronised.
        """
        dai = self.dai
        queues = list(self._queues.values())
        if not queues:
            raise DeviceError(f"OAK {self.mxid} is not streaming: start() first")
        try:
            if timeout > 0 and not any(q.has() for q in queues):
                dai.MessageQueue.waitAny(queues, datetime.timedelta(seconds=timeout))
            got = {socket: q.tryGetAll() for socket, q in self._queues.items()}
        except (dai.MessageQueue.QueueException, RuntimeError) as exc:
            raise DeviceDisconnected(
                f"OAK {self.mxid} went away while streaming ({exc}): check its cable and "
                "power, then start again"
            ) from exc
        middle = dai.CameraExposureOffset.MIDDLE
        out: list[OakFrameLike] = []
        for socket, msgs in got.items():
            if msgs and socket not in self._checked:
                self._check_first(socket, msgs[0])
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

    def _check_first(self, socket: str, frame: Any) -> None:
        """Record the first image's format and FSIN mode; refuse it unsynchronised
        (and every later image of that camera, which is checked again)."""
        fsync = frame.getFsync().name
        self.info[f"format.{socket}"] = (
            f"{frame.getType().name} {frame.getWidth()}x{frame.getHeight()}"
        )
        self.info[f"fsync.{socket}"] = fsync
        settings = self._settings
        wants_fsync = settings is not None and settings.sync != "off"
        if wants_fsync and settings is not None and not settings.allow_unsynced and fsync == "NONE":
            raise DeviceError(
                f"OAK {self.mxid} {socket}: FSIN {settings.sync} was set but its first image "
                "was not taken under frame sync (ImgFrame.getFsync() is NONE): check the "
                "FSIN cable and the master, or pass CameraSettings(allow_unsynced=True)"
            )
        self._checked.add(socket)

    def stop(self) -> None:
        """Stop the pipeline and release the board; :meth:`start` rebuilds both."""
        pipeline, self._pipeline = self._pipeline, None
        device, self._device = self._device, None
        self._queues = {}
        try:
            if pipeline is not None:
                pipeline.stop()
        finally:
            if device is not None:
                device.close()

    def close(self) -> None:
        """Stop and release the board (safe twice); :meth:`open` must come before a start."""
        self.stop()
        self._settings = None


def _ns(delta: Any) -> int:
    return (delta.days * 86_400 + delta.seconds) * 1_000_000_000 + delta.microseconds * 1000
