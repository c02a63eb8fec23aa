"""Conformance suite of the video-centroid (CEN) family (docs/protocols/centroid.md).

Runs against the simulator in CI and against a real hub on a bench
(``pytest tests/conformance --hw centroid=/dev/ttyUSB2``). Subclass
:class:`CentroidConformance` and provide a ``centroid_port`` fixture that yields
a device path or pyserial URL (the hub should see at least one marker). The
tests leave the hub stopped and reset.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest
import serial

from spotlab.core.errors import DeviceError
from spotlab.core.frames import FrameBlock
from spotlab.drivers.centroid import CentroidDriver, blobs_from_blocks
from spotlab.testing.wire import ask, reset
from spotlab.testing.wire import command as wire_command


class CentroidConformance:
    """Tests every CEN hub must pass. Needs a ``centroid_port`` fixture."""

    @pytest.fixture
    def link(self, centroid_port: str) -> Iterator[serial.Serial]:
        port = serial.serial_for_url(centroid_port, baudrate=9600, timeout=0.05)
        try:
            reset(port)
            yield port
        finally:
            try:
                port.write(wire_command("STOP:"))
                port.write(wire_command("RESET:"))
                port.flush()
            finally:
                port.close()

    def test_version_reply_names_the_family_and_camera_clock(self, link: serial.Serial) -> None:
        fields = ask(link, "VER:0").split()
        assert fields[0] == "CEN" and len(fields) == 6, fields
        assert 1 <= int(fields[3]) <= 16 and 1 <= int(fields[4]) <= 1024
        assert int(fields[5]) == 1_000_000

    def test_out_of_range_and_malformed_parameters(self, link: serial.Serial) -> None:
        assert ask(link, "RATE:999") == "ERROR23"
        assert ask(link, "CAMS:0") == "ERROR23"
        assert ask(link, "CAMS:65536") == "ERROR23"
        assert ask(link, "EXPO:19") == "ERROR23"
        assert ask(link, "THRS:255") == "ERROR23"
        assert ask(link, "BLOB:1025") == "ERROR23"
        assert ask(link, "BLOB:1,2") == "ERROR07"
        assert ask(link, "BOGUS:1") == "ERROR01"

    def test_configuration_commands_are_accepted(self, link: serial.Serial) -> None:
        for text in ("RATE:300000", "CAMS:1", "EXPO:800", "THRS:100", "BLOB:64", "INIT:"):
            assert ask(link, text) == "OKAY", text

    def test_start_checks_exposure_and_bandwidth(self, link: serial.Serial) -> None:
        assert ask(link, "RATE:1000000") == "OKAY"
        assert ask(link, "EXPO:1000") == "OKAY"
        assert ask(link, "START:") == "ERROR23"  # 1 ms exposure in a 1 ms period
        assert ask(link, "EXPO:500") == "OKAY"
        assert ask(link, "START:") == "ERROR80"  # 1 kHz frames need more than 9600 baud

    def test_driver_streams_blob_frames(self, centroid_port: str) -> None:
        driver = CentroidDriver(centroid_port, cameras=2, rate_hz=100.0, max_blobs=128)
        with driver:
            blocks: list[FrameBlock] = []
            while sum(len(b) for b in blocks) < 40:
                block = driver.recv(timeout=2.0)
                assert block is not None, "no hub frames within 2 s"
                blocks.append(block)
            with pytest.raises(DeviceError) as info:
                driver.command("BLOB:8")
            assert info.value.code == 0x0C
        blobs = blobs_from_blocks(blocks)
        assert np.all(np.diff(blobs.seq) == 1)
        assert abs(np.median(np.diff(blobs.ticks)) - 10_000) < 10
        # Each camera's own clock advances by one period per frame (within 200 ppm).
        step = np.diff(blobs.exposure_us, axis=0)
        assert np.nanmax(np.abs(step - 10_000)) < 2 + 10_000 * 2e-4
        assert (blobs.counts <= 128).all() and blobs.counts.sum() > 0
        assert driver.stats.crc_errors == 0 and driver.stats.lost_frames == 0
