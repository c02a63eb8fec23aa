"""A stand-in for the depthai module that runs OAK boards on the host.

Where depthai works without a board, its real objects are used: the pipeline is a
real host-only ``dai.Pipeline(False)`` (it refuses a second ``start()`` and closes
its queues on ``stop()``, as on a board), each camera is a real ``ThreadedHostNode``
sending real ``dai.ImgFrame`` messages into real ``dai.MessageQueue`` output queues
(which raise ``MessageQueue.QueueException`` once closed, as after an unplug),
``initialControl`` is a real ``dai.CameraControl`` and device lists are real
``dai.DeviceInfo``. Only what needs a board is faked: the ``Device`` connection,
``Camera`` nodes (depthai refuses device nodes in a host-only pipeline) and the
device list XLink would return. Written from depthai 3.12's documented behaviour
(docs/oak.md), not from the driver.
"""

from __future__ import annotations

import datetime
import importlib
import os
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from types import SimpleNamespace
from typing import Any

import numpy as np

__all__ = ["FakeBoard", "FakeDepthai"]

#: FSIN mode a sensor's images report (``ImgFrame.Fsync``) for the mode it was given.
_REPORTED = {"OUTPUT": "OUTPUT", "INPUT": "INPUT"}


@dataclass
class FakeBoard:
    """One OAK board as XLink and the sensors would present it.

    Attributes
    ----------
    mxid : str
        Device id; XLink reports ``""`` for a board without permission.
    name : str
        USB path (``"1.2"``).
    permitted : bool
        False: the udev rule is missing (status ``X_LINK_INSUFFICIENT_PERMISSIONS``).
    in_use : bool
        True: another process booted it (state ``X_LINK_BOOTED``; connecting fails).
    build_error : Exception, optional
        Raised by ``Camera.build`` (an unsupported socket or rate).
    dead : set of str
        Sockets whose sensor never delivers.
    fsync_effective : bool
        False: images report ``Fsync.NONE`` whatever mode was set.
    n_frames : int, optional
        Images per camera before the sensor falls silent.
    usb_speed, sensor : str
        What ``getUsbSpeed`` and ``getCameraSensorNames`` answer.
    """

    mxid: str
    name: str = "1.1"
    permitted: bool = True
    in_use: bool = False
    build_error: Exception | None = None
    dead: set[str] = field(default_factory=set)
    fsync_effective: bool = True
    n_frames: int | None = None
    usb_speed: str = "SUPER"
    sensor: str = "OV9282"
    #: Pipelines built on this board, newest last (for tests to inspect and unplug).
    pipelines: list[FakePipeline] = field(default_factory=list)
    connections: int = 0
    closed: int = 0

    def info(self, dai: Any) -> Any:
        """The real ``dai.DeviceInfo`` XLink would list for this board."""
        status = "X_LINK_SUCCESS" if self.permitted else "X_LINK_INSUFFICIENT_PERMISSIONS"
        state = "X_LINK_BOOTED" if self.in_use else "X_LINK_UNBOOTED"
        return dai.DeviceInfo(
            self.name, self.mxid if self.permitted else "",
            getattr(dai.XLinkDeviceState, state), dai.XLinkProtocol.X_LINK_USB_VSC,
            dai.XLinkPlatform.X_LINK_MYRIAD_X, getattr(dai.XLinkError_t, status),
        )  # fmt: skip

    def unplug(self) -> None:
        """Pull the cable: the running pipeline's queues close."""
        for pipeline in self.pipelines:
            pipeline.unplug()


class FakeDepthai:
    """What the OAK driver uses of the depthai module, for boards that are not there.

    Every attribute not overridden here is the real depthai's (enums, ``ImgFrame``,
    ``CameraControl``, ``MessageQueue``, ``DeviceInfo``, ...).

    Parameters
    ----------
    boards : sequence of FakeBoard
        The boards on the bus.
    """

    def __init__(self, boards: Sequence[FakeBoard]) -> None:
        os.environ.setdefault("DEPTHAI_LEVEL", "error")  # as depthai_module() does
        self._dai = importlib.import_module("depthai")
        self.boards = list(boards)
        fake = self

        class Device:
            """A connection to a board (``dai.Device(DeviceInfo)``)."""

            def __init__(self, info: Any) -> None:
                self.board = fake._connect(info)
                self._closed = False

            def getUsbSpeed(self) -> Any:
                return getattr(fake._dai.UsbSpeed, self.board.usb_speed)

            def getCameraSensorNames(self) -> dict[Any, str]:
                sockets = fake._dai.CameraBoardSocket
                return {sockets.CAM_B: self.board.sensor, sockets.CAM_C: self.board.sensor}

            def close(self) -> None:
                if not self._closed:
                    self._closed = True
                    self.board.closed += 1

            def isClosed(self) -> bool:
                return self._closed

            @staticmethod
            def getAllAvailableDevices() -> list[Any]:
                return [b.info(fake._dai) for b in fake.boards if b.permitted and not b.in_use]

        self.Device = Device
        self.XLinkConnection = SimpleNamespace(getAllConnectedDevices=self._connected)
        self.node = SimpleNamespace(Camera=FakeCameraNode)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._dai, name)

    def Pipeline(self, device: Any) -> FakePipeline:
        """A pipeline on ``device``: a real host-only pipeline underneath."""
        pipeline = FakePipeline(self._dai, device.board)
        device.board.pipelines.append(pipeline)
        return pipeline

    def _connected(
        self, state: Any = None, skip_invalid: bool = True, timeout_ms: int = 500
    ) -> list[Any]:
        return [b.info(self._dai) for b in self.boards if b.permitted or not skip_invalid]

    def _connect(self, info: Any) -> FakeBoard:
        for board in self.boards:
            if board.mxid == info.deviceId and board.permitted:
                if board.in_use:
                    raise RuntimeError(
                        f'Cannot connect to device with name "{board.name}", it is used by '
                        "another process. Error: X_LINK_DEVICE_ALREADY_IN_USE"
                    )
                board.connections += 1
                return board
        raise RuntimeError(
            f"Failed to find device ({info.deviceId}), error message: X_LINK_DEVICE_NOT_FOUND"
        )


class FakePipeline:
    """``dai.Pipeline(device)`` for a fake board: a real host-only pipeline with one
    host node per camera."""

    def __init__(self, dai: Any, board: FakeBoard) -> None:
        self._dai = dai
        self.board = board
        self.real = dai.Pipeline(False)
        self.cameras: list[FakeCameraNode] = []
        #: Set to end the sensor loops before the real pipeline stops: depthai 3.12
        #: aborts the interpreter at exit if a host node was stopped mid-loop.
        self.halt = threading.Event()

    def create(self, kind: type[FakeCameraNode]) -> FakeCameraNode:
        """A ``Camera`` node (the only node kind the OAK driver creates)."""
        cam = kind(self)
        self.cameras.append(cam)
        return cam

    def start(self) -> None:
        """Start the host nodes; a second start raises depthai's own RuntimeError."""
        self.real.start()

    def stop(self) -> None:
        """Stop the host nodes; their queues close."""
        self.halt.set()
        self.real.stop()
        self.real.wait()

    def isRunning(self) -> bool:
        return bool(self.real.isRunning())

    def unplug(self) -> None:
        """The board went away: the queues close under the reader."""
        if self.real.isRunning():
            self.stop()


class FakeCameraNode:
    """``dai.node.Camera`` on a fake board; ``initialControl`` is a real ``CameraControl``."""

    def __init__(self, pipeline: FakePipeline) -> None:
        self.pipeline = pipeline
        self.initialControl = pipeline._dai.CameraControl()
        self.socket = ""
        self.fps = 0.0

    def build(self, socket: Any, sensorFps: float | None = None) -> FakeCameraNode:
        """Bind the node to ``socket`` (raises the board's ``build_error``)."""
        if self.pipeline.board.build_error is not None:
            raise self.pipeline.board.build_error
        self.socket = socket.name
        self.fps = float(sensorFps or 30.0)
        return self

    def requestOutput(self, size: tuple[int, int], type: Any, fps: float | None = None) -> Any:
        """A real host node that sends this camera's images at ``fps``."""
        node = self.pipeline.real.create(_sensor_node_class(self.pipeline._dai))
        node.build(self, (int(size[0]), int(size[1])), float(fps or self.fps))
        return node.out


_SENSOR_NODE: dict[int, type] = {}
_LOCK = threading.Lock()


def _sensor_node_class(dai: Any) -> type:
    """The ThreadedHostNode subclass standing for a sensor (defined once depthai is imported)."""
    with _LOCK:
        if id(dai) in _SENSOR_NODE:
            return _SENSOR_NODE[id(dai)]

        class SensorNode(dai.node.ThreadedHostNode):
            def __init__(self) -> None:
                super().__init__()
                self.out = self.createOutput()

            def build(self, cam: FakeCameraNode, size: tuple[int, int], fps: float) -> Any:
                self.cam, self.size, self.period = cam, size, 1.0 / fps
                return self

            def run(self) -> None:
                _emit(dai, self)

        _SENSOR_NODE[id(dai)] = SensorNode
        return SensorNode


def _emit(dai: Any, node: Any) -> None:
    """The sensor loop: one GRAY8 image per period, stamped as depthai stamps them."""
    cam: FakeCameraNode = node.cam
    board = cam.pipeline.board
    if cam.socket in board.dead:
        cam.pipeline.halt.wait()
        return
    control = cam.initialControl
    fsync = _REPORTED.get(control.frameSyncMode.name, "NONE") if board.fsync_effective else "NONE"
    exposure_us = int(control.getExposureTime().total_seconds() * 1e6 + 0.5)
    width, height = node.size
    start = time.monotonic()
    k = 0
    halt = cam.pipeline.halt
    while not halt.is_set() and (board.n_frames is None or k < board.n_frames):
        mid_s = start + k * node.period
        frame = dai.ImgFrame()
        frame.setFrame(np.full((height, width), 6, np.uint8))
        frame.setType(dai.ImgFrame.Type.GRAY8)
        frame.setWidth(width)
        frame.setHeight(height)
        frame.setSequenceNum(k)
        meta = frame.cam
        meta.exposureTimeUs = exposure_us
        meta.sensitivityIso = control.getSensitivity()
        meta.fsync = getattr(dai.ImgFrame.Fsync, fsync)
        frame.cam = meta
        # depthai stamps the end of the exposure; getTimestamp(MIDDLE) subtracts half.
        end = datetime.timedelta(seconds=mid_s + exposure_us / 2e6)
        frame.setTimestamp(end)
        frame.setTimestampDevice(end + datetime.timedelta(seconds=12.5))
        node.out.send(frame)
        k += 1
        halt.wait(max(0.0, start + k * node.period - time.monotonic()))
