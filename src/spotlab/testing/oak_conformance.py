"""Conformance suite of the OAK driver: a fake board in CI, real boards on a bench.

``pytest tests/conformance/test_oak.py --hw oak=MXID[,MXID...]`` runs it on hardware
(point the cameras at a few markers, lights on the markers, room dark). Subclass
:class:`OakConformance` and provide an ``oak_driver`` fixture that yields an
unstarted :class:`~spotlab.drivers.oak.OakDriver`.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from spotlab.acquisition.recorder import Recorder
from spotlab.acquisition.replay import replay
from spotlab.acquisition.session import Session
from spotlab.core.frames import FrameBlock
from spotlab.drivers.oak import FLAG_OFFLINE, OakDriver, decoder_from_metadata

#: Frames every test waits for.
FRAMES = 12


def _frames(driver: OakDriver, n: int = FRAMES, timeout_s: float = 10.0) -> FrameBlock:
    blocks: list[FrameBlock] = []
    got = 0
    while got < n:
        block = driver.recv(timeout=timeout_s)
        assert block is not None, f"no frame within {timeout_s} s after {got}"
        blocks.append(block)
        got += len(block)
    return FrameBlock.concat(blocks)


class OakConformance:
    """Tests every OAK set-up must pass. Needs an ``oak_driver`` fixture."""

    def test_stream_is_blobs2d_with_one_sensor_per_camera(self, oak_driver: OakDriver) -> None:
        with oak_driver:
            spec = oak_driver.spec
            block = _frames(oak_driver)
        assert spec.kind == "blobs2d" and spec.n_sensors == len(oak_driver.cameras)
        assert block.data.shape[1:] == (spec.n_markers, spec.n_sensors, len(spec.values))
        json.dumps(oak_driver.metadata())

    def test_frames_are_in_order_at_the_frame_rate(self, oak_driver: OakDriver) -> None:
        with oak_driver:
            block = _frames(oak_driver)
        assert np.all(np.diff(block.seq) == 1)
        period = np.diff(block.ticks) / 1e9
        np.testing.assert_allclose(np.median(period), 1.0 / oak_driver.settings.fps, rtol=0.02)

    def test_cameras_expose_together(self, oak_driver: OakDriver) -> None:
        # FSIN: every camera's exposure mid-point within 1 ms of the frame time.
        with oak_driver:
            block = _frames(oak_driver)
        online = (block.flags[:, 0, :] & FLAG_OFFLINE) == 0
        assert online.mean() > 0.9
        dt = block.data[..., 4]
        assert np.nanmax(np.abs(dt)) < 1e-3

    def test_every_camera_sees_blobs_inside_its_image(self, oak_driver: OakDriver) -> None:
        with oak_driver:
            block = _frames(oak_driver)
        w, h = oak_driver.settings.size
        x, y = block.data[..., 0], block.data[..., 1]
        seen = ~np.isnan(x)
        assert np.all(seen.any(axis=(0, 1))), "a camera saw no blob in any frame"
        assert np.all((x[seen] >= 0) & (x[seen] <= w - 1) & (y[seen] >= 0) & (y[seen] <= h - 1))

    def test_a_recording_replays_to_the_same_blocks(
        self, oak_driver: OakDriver, tmp_path: Path
    ) -> None:
        out = tmp_path / "oak.spj"
        got: list[FrameBlock] = []

        class Keep:
            def on_block(self, stream: str, block: FrameBlock) -> None:
                got.append(block)

            def on_error(self, stream: str, exc: BaseException) -> None:
                raise AssertionError(exc)

            def stop(self) -> None:
                pass

        with Session([oak_driver], [Recorder(out), Keep()], close_devices=True) as session:
            deadline = 200
            while session.frames[oak_driver.name] < FRAMES and deadline:
                import time

                time.sleep(0.05)
                deadline -= 1
            session.stop()
        live = FrameBlock.concat(got)
        again = FrameBlock.concat(
            [b for _, b in replay(out, lambda meta: decoder_from_metadata(meta))]
        )
        assert len(live) >= FRAMES
        for field in ("seq", "ticks", "arrival_ns", "data", "flags", "status"):
            np.testing.assert_array_equal(getattr(again, field), getattr(live, field))

    def test_boards_report_usb3_the_asked_format_and_fsync(self, oak_driver: OakDriver) -> None:
        # What only a board can tell: depthai's getUsbSpeed and each camera's first
        # ImgFrame (type, size, getFsync). Two 1280x800 GRAY8 cameras need USB 3.
        with oak_driver:
            _frames(oak_driver)
            reported = [dict(b.info) for b in oak_driver.boards]
        w, h = oak_driver.settings.size
        for board, info in zip(oak_driver.boards, reported, strict=True):
            assert info["usb_speed"] in ("SUPER", "SUPER_PLUS"), info
            for socket in board.sockets:
                assert info[f"format.{socket}"] == f"GRAY8 {w}x{h}", info
            synced = len(oak_driver.boards) > 1 or oak_driver.settings.sync != "off"
            if synced:
                modes = [info[f"fsync.{s}"] for s in board.sockets]
                assert "NONE" not in modes, info
        meta = oak_driver.metadata()
        assert [b["reported"]["usb_speed"] for b in meta["boards"]] == [
            i["usb_speed"] for i in reported
        ]

    def test_start_after_stop_streams_again(self, oak_driver: OakDriver) -> None:
        oak_driver.start()
        first = _frames(oak_driver, 2)
        oak_driver.stop()
        oak_driver.start()
        again = _frames(oak_driver, 2)
        oak_driver.close()
        assert again.ticks[0] > first.ticks[-1]

    def test_close_twice_is_safe(self, oak_driver: OakDriver) -> None:
        oak_driver.start()
        _frames(oak_driver, 2)
        oak_driver.close()
        oak_driver.close()
