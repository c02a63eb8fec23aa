"""DepthaiCamera against FakeDepthai: real depthai queues, frames, controls and a
host-only pipeline, with only the board connection faked (issue 20, points 1-7)."""

from __future__ import annotations

import datetime
from collections.abc import Iterator

import numpy as np
import pytest

from spotlab.core.errors import ConfigurationError, DeviceDisconnected, DeviceError, DeviceNotFound
from spotlab.drivers.oak import (
    FLAG_OFFLINE,
    CameraSettings,
    OakDriver,
    OakInUseError,
    UsbPermissionError,
)
from spotlab.drivers.oak.depthai_camera import DepthaiCamera, find_devices, fsync_modes
from spotlab.drivers.oak.driver import MAX_WAIT_PERIODS

pytest.importorskip("depthai", reason="the oak extra is not installed")
from spotlab.simulators.oak_depthai import FakeBoard, FakeDepthai


def _settings(**kw: object) -> CameraSettings:
    """Small images at 20 Hz: the host nodes stay cheap on a busy machine."""
    return CameraSettings(**{"size": (64, 40), "fps": 20.0, **kw})


@pytest.fixture
def cameras() -> Iterator[list[DepthaiCamera]]:
    """Cameras a test opened; closed after it, so no host node outlives the test."""
    made: list[DepthaiCamera] = []
    yield made
    for cam in made:
        cam.close()


def _camera(made: list[DepthaiCamera], board: FakeBoard, *others: FakeBoard) -> DepthaiCamera:
    cam = DepthaiCamera(board.mxid, dai=FakeDepthai([board, *others]))
    made.append(cam)
    return cam


def _modes(board: FakeBoard) -> list[str]:
    return [c.initialControl.frameSyncMode.name for c in board.pipelines[-1].cameras]


# 1. FSIN ---------------------------------------------------------------------------
def test_master_drives_fsin_from_one_sensor_slaves_follow_and_off_is_explicit(
    cameras: list[DepthaiCamera],
) -> None:
    want = {"master": ["OUTPUT", "INPUT"], "slave": ["INPUT", "INPUT"], "off": ["OFF", "OFF"]}
    for sync, modes in want.items():
        board = FakeBoard("MX1")
        _camera(cameras, board).open(_settings(sync=sync))
        assert _modes(board) == modes, sync
    assert fsync_modes("master", ("CAM_A", "CAM_B", "CAM_C")) == {
        "CAM_A": "OUTPUT", "CAM_B": "INPUT", "CAM_C": "INPUT",
    }  # fmt: skip


# 2. Permissions ----------------------------------------------------------------------
def test_a_board_without_permission_is_listed_and_named_with_the_udev_command(
    cameras: list[DepthaiCamera],
) -> None:
    denied = FakeBoard("MX1", name="1.4", permitted=False)
    dai = FakeDepthai([denied])
    assert dai.Device.getAllAvailableDevices() == []  # what depthai leaves out
    assert find_devices(dai) == [("", "1.4", "X_LINK_UNBOOTED", "X_LINK_INSUFFICIENT_PERMISSIONS")]
    cam = _camera(cameras, denied)
    with pytest.raises(UsbPermissionError, match=r"USB 1\.4.*spotlab udev install"):
        cam.open(_settings())
    assert denied.connections == 0
    other = DepthaiCamera("MX9", dai=FakeDepthai([FakeBoard("MX1")]))
    cameras.append(other)
    with pytest.raises(DeviceNotFound, match=r"MxId MX9.*seen: MX1 \(X_LINK_UNBOOTED\)"):
        other.open(_settings())


# 3. A dead camera -------------------------------------------------------------------
def test_a_dead_sensor_does_not_hold_up_the_live_one(cameras: list[DepthaiCamera]) -> None:
    # 20 images at 20 Hz into an 8-image queue: waiting on the dead CAM_B for the full
    # timeout (2 s) would let 12 of CAM_C's images be dropped.
    board = FakeBoard("MX1", dead={"CAM_B"}, n_frames=20)
    cam = _camera(cameras, board)
    cam.open(_settings())
    cam.start()
    seqs: list[int] = []
    empty = 0
    while 19 not in seqs and empty < 2:
        got = cam.frames(2.0)
        empty += not got
        assert all(f.socket == "CAM_C" for f in got)
        seqs += [f.seq for f in got]
    assert seqs == list(range(20))


# 4. Restart -------------------------------------------------------------------------
def test_start_after_stop_rebuilds_the_pipeline(cameras: list[DepthaiCamera]) -> None:
    board = FakeBoard("MX1")
    cam = _camera(cameras, board)
    cam.open(_settings())
    cam.start()
    with pytest.raises(RuntimeError, match="already running"):
        board.pipelines[-1].start()  # the real depthai refuses a second start
    assert cam.frames(2.0)
    cam.stop()
    assert not board.pipelines[-1].isRunning() and board.closed == 1
    cam.start()
    assert cam.frames(2.0)
    assert len(board.pipelines) == 2 and board.connections == 2


def test_the_driver_streams_again_after_stop() -> None:
    board = FakeBoard("MX1")
    cam = DepthaiCamera("MX1", dai=FakeDepthai([board]))
    driver = OakDriver("MX1", boards=[cam], settings=_settings())
    try:
        for _ in range(2):
            driver.start()
            assert driver.recv(timeout=2.0) is not None or driver.recv(timeout=2.0) is not None
            driver.stop()
    finally:
        driver.close()
    assert board.closed == 2


# 5. Units ---------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("field", "value", "match"),
    [
        ("exposure_us", 500.0, "must be an int.*seconds"),
        ("iso", 400.0, "iso must be an int"),
        ("iso", 50, "iso=50 is outside 100-1600"),
        ("exposure_us", 0, "outside"),
        ("exposure_us", 9000, "longer than a frame at 120"),
        ("fps", float("nan"), "fps=nan"),
        ("sync", "both", "master, slave or off"),
    ],
)
def test_camera_settings_refuse_wrong_units_and_ranges(
    field: str, value: object, match: str
) -> None:
    with pytest.raises(ConfigurationError, match=match):
        CameraSettings(**{field: value})


def test_exposure_reaches_depthai_in_microseconds(cameras: list[DepthaiCamera]) -> None:
    board = FakeBoard("MX1")
    _camera(cameras, board).open(_settings(exposure_us=300, iso=800))
    for node in board.pipelines[-1].cameras:
        control = node.initialControl  # a real dai.CameraControl
        assert control.getExposureTime() == datetime.timedelta(microseconds=300)
        assert control.getSensitivity() == 800


# 6. Errors --------------------------------------------------------------------------
def test_a_failed_build_releases_the_board_and_raises_a_device_error(
    cameras: list[DepthaiCamera],
) -> None:
    board = FakeBoard(
        "MX1", build_error=RuntimeError("Camera socket not found on the connected device")
    )
    cam = _camera(cameras, board)
    with pytest.raises(DeviceError, match=r"could not be built.*socket not found.*released"):
        cam.open(_settings())
    assert board.connections == board.closed == 1


def test_a_board_held_by_another_process_reads_in_use(cameras: list[DepthaiCamera]) -> None:
    board = FakeBoard("MX1", in_use=True)
    assert FakeDepthai([board]).Device.getAllAvailableDevices() == []
    with pytest.raises(OakInUseError, match="MX1 is in use by another process"):
        _camera(cameras, board).open(_settings())


def test_an_unplug_is_a_disconnect_and_the_driver_says_so() -> None:
    board = FakeBoard("MX1")
    cam = DepthaiCamera("MX1", dai=FakeDepthai([board]))
    driver = OakDriver("MX1", boards=[cam], settings=_settings())
    events: list[str] = []

    class Tap:
        def on_rx(self, stream: str, data: bytes, t_ns: int) -> None:
            pass

        def on_tx(self, stream: str, data: bytes, t_ns: int) -> None:
            pass

        def on_event(self, stream: str, kind: str, detail: dict, t_ns: int) -> None:
            events.append(kind)

    driver.add_tap(Tap())
    try:
        driver.start()
        board.unplug()
        with pytest.raises(DeviceDisconnected, match=r"MX1 went away.*MessageQueue"):
            for _ in range(50):
                driver.recv(timeout=0.5)
    finally:
        driver.close()
    assert "disconnected" in events


# 7. What only a board can tell ------------------------------------------------------
def test_unsynchronised_images_are_refused_unless_allowed(cameras: list[DepthaiCamera]) -> None:
    board = FakeBoard("MX1", fsync_effective=False)
    cam = _camera(cameras, board)
    cam.open(_settings(sync="master"))
    cam.start()
    for _ in range(2):  # and again on the next read: refused for good
        with pytest.raises(DeviceError, match=r"getFsync\(\) is NONE.*allow_unsynced"):
            for _ in range(20):
                cam.frames(2.0)
    cam.close()
    cam.open(_settings(sync="master", allow_unsynced=True))
    cam.start()
    for _ in range(20):
        if "fsync.CAM_C" in cam.info and "fsync.CAM_B" in cam.info:
            break
        cam.frames(2.0)
    assert cam.info["fsync.CAM_B"] == cam.info["fsync.CAM_C"] == "NONE"


def test_usb_speed_sensors_format_and_fsync_are_reported(cameras: list[DepthaiCamera]) -> None:
    board = FakeBoard("MX1", usb_speed="HIGH")
    cam = _camera(cameras, board)
    cam.open(_settings(sync="master"))
    cam.start()
    assert cam.info == {"usb_speed": "HIGH", "sensor.CAM_B": "OV9282", "sensor.CAM_C": "OV9282"}
    for _ in range(20):
        if len(cam.info) == 7:
            break
        cam.frames(2.0)
    assert cam.info["format.CAM_B"] == cam.info["format.CAM_C"] == "GRAY8 64x40"
    assert (cam.info["fsync.CAM_B"], cam.info["fsync.CAM_C"]) == ("OUTPUT", "INPUT")


def test_a_dead_board_does_not_hold_up_the_live_one() -> None:
    # Board 0 never delivers; board 1 sends 20 images per camera at 20 Hz into
    # 8-image queues. Waiting on board 0 for the whole timeout would drop 12 of them.
    dead = FakeBoard("MX0", name="1.1", dead={"CAM_B", "CAM_C"})
    live = FakeBoard("MX1", name="1.2", n_frames=20)
    dai = FakeDepthai([dead, live])
    boards = [DepthaiCamera(b.mxid, dai=dai) for b in (dead, live)]
    driver = OakDriver(
        "MX0,MX1", boards=boards, settings=_settings(allow_unsynced=True), max_blobs=4
    )
    seen: list[int] = []
    try:
        driver.start()
        for _ in range(40):
            block = driver.recv(timeout=2.0)
            if block is None:
                break
            online = (block.flags[:, 0, 2] & FLAG_OFFLINE) == 0
            seen += [int(t) for t in block.ticks[online]]
    finally:
        driver.close()
    # The last MAX_WAIT_PERIODS images wait for newer ones that never come (the board
    # fell silent); every one before them is there, one period apart.
    assert len(seen) == 20 - MAX_WAIT_PERIODS
    assert np.all(np.abs(np.diff(seen) - 50_000_000) <= 1000)
