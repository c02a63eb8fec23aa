"""OakDriver behind the seam: blobs against the fake board's truth, timestamps, a camera
that drops out, bad boards, the journal record, and depthai without a device."""

from __future__ import annotations

import time

import numpy as np
import pytest
from scipy.spatial import cKDTree

from spotlab.core.errors import DeviceNotFound
from spotlab.core.frames import FrameBlock
from spotlab.drivers.oak import (
    FLAG_OFFLINE,
    CameraSettings,
    OakDriver,
    OakInUseError,
    OakRecordDecoder,
    UsbPermissionError,
)
from spotlab.drivers.oak.depthai_camera import _check_found
from spotlab.simulators.motions import reference_markers
from spotlab.simulators.oak import FakeOakDevice, oak_rig


def _driver(**fake: object) -> tuple[OakDriver, FakeOakDevice]:
    rig = oak_rig(2, seed=3)
    board = FakeOakDevice("FAKE1", rig.cameras, reference_markers(6, seed=4), seed=5, **fake)  # type: ignore[arg-type]
    return OakDriver("FAKE1", boards=[board], settings=CameraSettings(fps=200.0)), board


def _take(driver: OakDriver, n: int) -> FrameBlock:
    blocks = []
    while sum(len(b) for b in blocks) < n:
        block = driver.recv(timeout=2.0)
        assert block is not None
        blocks.append(block)
    return FrameBlock.concat(blocks)


def test_blobs_are_the_projected_markers_and_times_the_exposure_mid_points() -> None:
    driver, board = _driver(noise=1.0)
    with driver:
        block = _take(driver, 4)
    for f in range(4):
        truth = board.truth_uv(f)
        for c in range(2):
            xy = block.data[f, :, c, :2]
            xy = xy[~np.isnan(xy[:, 0])]
            want = truth[c][~np.isnan(truth[c, :, 0])]
            assert len(xy) == len(want) > 0
            dist, _ = cKDTree(xy).query(want)
            assert dist.max() < 0.15
    np.testing.assert_array_equal(block.ticks, [board.exposure_mid_ns(k) for k in range(4)])
    assert np.nanmax(np.abs(block.data[..., 4])) == 0.0
    np.testing.assert_array_equal(block.seq, np.arange(4))


def test_a_camera_that_drops_out_is_flagged_offline_and_the_stream_goes_on() -> None:
    driver, _ = _driver(dropouts={"CAM_C": (2, 9)}, n_frames=14)
    with driver:
        block = _take(driver, 14)
    offline = (block.flags[:, 0, :] & FLAG_OFFLINE) != 0
    np.testing.assert_array_equal(np.flatnonzero(offline[:, 1]), np.arange(2, 9))
    assert not offline[:, 0].any()
    assert np.all(np.isnan(block.data[2:9, :, 1, 0]))
    np.testing.assert_array_equal(block.seq, np.arange(14))


def test_a_missing_board_raises_at_start_and_releases_the_others() -> None:
    driver, board = _driver(open_error=DeviceNotFound("no OAK with MxId FAKE1"))
    with pytest.raises(DeviceNotFound, match="FAKE1"):
        driver.start()
    assert board.closed


def test_record_decoder_resyncs_after_damage_and_counts_it() -> None:
    driver, _ = _driver(n_frames=3)
    records: list[bytes] = []

    class Tap:
        def on_rx(self, stream: str, data: bytes, t_ns: int) -> None:
            records.append(data)

        def on_tx(self, stream: str, data: bytes, t_ns: int) -> None:
            pass

        def on_event(self, stream: str, kind: str, detail: dict, t_ns: int) -> None:
            pass

    driver.add_tap(Tap())
    with driver:
        live = _take(driver, 3)
    wire = bytearray(b"".join(records))
    wire[20] ^= 0xFF  # inside the first record
    decoder = OakRecordDecoder(driver.spec)
    out = [decoder.feed(bytes(wire[i : i + 7]), 0) for i in range(0, len(wire), 7)]
    again = FrameBlock.concat([b for b in out if len(b)])
    np.testing.assert_array_equal(again.seq, [1, 2])
    np.testing.assert_array_equal(again.data, live.data[1:])
    assert decoder.stats.crc_errors == 1 and decoder.stats.lost_frames == 0


def test_found_devices_are_checked_by_mxid_permission_and_owner() -> None:
    with pytest.raises(DeviceNotFound, match=r"MxId 14442C1.*seen: none.*udev"):
        _check_found("14442C1", [])
    denied = ("", "1.3", "X_LINK_UNBOOTED", "X_LINK_INSUFFICIENT_PERMISSIONS")
    # XLink cannot read the MxId of a board it may not open: any such board is the hint.
    with pytest.raises(UsbPermissionError, match=r"USB 1\.3.*spotlab udev install"):
        _check_found("14442C1", [denied])
    with pytest.raises(OakInUseError, match="in use by another process"):
        _check_found("14442C1", [("14442C1", "1.3", "X_LINK_BOOTED", "X_LINK_SUCCESS")])
    _check_found("14442C1", [("14442C1", "1.3", "X_LINK_UNBOOTED", "X_LINK_SUCCESS")])


def test_the_driver_restarts_after_stop() -> None:
    driver, board = _driver(n_frames=50)
    with driver:
        _take(driver, 2)
        driver.stop()
        assert not board.started
        driver.start()
        _take(driver, 2)
    assert board.starts == 2


def test_depthai_without_a_device_gives_the_clear_error_quickly() -> None:
    pytest.importorskip("depthai", reason="the oak extra is not installed")
    driver = OakDriver("NOSUCHMXID0001")
    start = time.monotonic()
    with pytest.raises(DeviceNotFound, match="NOSUCHMXID0001"):
        driver.start()
    assert time.monotonic() - start < 30
    assert OakDriver.detect() == []
