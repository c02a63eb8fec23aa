"""Conformance suite of the lateral-photodiode (SPX) family.

The same tests run against the simulator in CI and against a real device on a
bench (``pytest tests/conformance --hw selspot=/dev/ttyUSB0``). Subclass
:class:`SelspotConformance` and provide a ``selspot_port`` fixture that yields
a device path or pyserial URL. The tests only configure small, safe set-ups
and always leave the device stopped.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest
import serial

from spotlab.core.errors import DeviceError
from spotlab.drivers.selspot import SelspotDriver
from spotlab.testing.wire import ask, check_reply, command, read_until, reset

ERROR_INVALID_COMMAND = "ERROR01"
ERROR_BAD_CRC = "ERROR04"
ERROR_NOT_IN_THIS_MODE = "ERROR0C"
ERROR_OUT_OF_RANGE = "ERROR23"
ERROR_BANDWIDTH = "ERROR80"
ERROR_BAD_LED_TABLE = "ERROR81"
ERROR_NOT_CONFIGURED = "ERROR82"


class SelspotConformance:
    """Tests every SPX device must pass. Needs a ``selspot_port`` fixture."""

    @pytest.fixture
    def link(self, selspot_port: str) -> Iterator[serial.Serial]:
        port = serial.serial_for_url(selspot_port, baudrate=9600, timeout=0.05)
        try:
            reset(port)
            yield port
        finally:
            try:
                port.write(command("STOP:"))
                port.write(command("RESET:"))
                port.flush()
            finally:
                port.close()

    # -- command layer (MCS-1 §3) ------------------------------------------
    def test_version_reply_names_the_family(self, link: serial.Serial) -> None:
        fields = ask(link, "VER:0").split()
        assert fields[0] == "SPX", fields
        assert len(fields) == 5, fields
        assert 1 <= int(fields[3]) <= 4 and 1 <= int(fields[4]) <= 128

    def test_unknown_command_is_error_01(self, link: serial.Serial) -> None:
        assert ask(link, "BOGUS:1") == ERROR_INVALID_COMMAND

    def test_bad_crc_is_error_04(self, link: serial.Serial) -> None:
        link.write(b"VER:00000\r")
        assert check_reply(read_until(link, b"\r", 1.0)) == ERROR_BAD_CRC

    def test_space_form_needs_no_crc(self, link: serial.Serial) -> None:
        link.write(b"VER 0\r")
        assert check_reply(read_until(link, b"\r", 1.0)).startswith("SPX ")

    def test_out_of_range_parameters_are_error_23(self, link: serial.Serial) -> None:
        assert ask(link, "CAMS:5") == ERROR_OUT_OF_RANGE
        assert ask(link, "SLOT:20") == ERROR_OUT_OF_RANGE
        assert ask(link, "BGND:3") == ERROR_OUT_OF_RANGE

    def test_bad_led_tables_are_error_81(self, link: serial.Serial) -> None:
        assert ask(link, "LEDT:0080") == "OKAY"
        assert ask(link, "LEDT:00800080") == ERROR_BAD_LED_TABLE  # id twice
        assert ask(link, "LEDT:8080") == ERROR_BAD_LED_TABLE  # id above 7F
        assert ask(link, "LEDT:008") == ERROR_BAD_LED_TABLE  # not a multiple of 4

    def test_led_table_reads_back(self, link: serial.Serial) -> None:
        assert ask(link, "LEDT:008005C01140") == "OKAY"
        assert ask(link, "LEDQ:") == "LEDQ 008005C01140"

    def test_start_without_led_table_is_error_82(self, link: serial.Serial) -> None:
        assert ask(link, "START:") == ERROR_NOT_CONFIGURED

    def test_bandwidth_is_checked_at_start(self, link: serial.Serial) -> None:
        # 4 cameras x 32 LEDs at 200 Hz need 1.34 Mbit/s; 9600 baud cannot carry it.
        assert ask(link, "CAMS:4") == "OKAY"
        table = "".join(f"{i:02X}80" for i in range(32))
        assert ask(link, f"LEDT:{table}") == "OKAY"
        assert ask(link, "RATE:200000") == "OKAY"
        assert ask(link, "START:") == ERROR_BANDWIDTH

    def test_timing_is_checked_at_start(self, link: serial.Serial) -> None:
        # 128 LEDs of 100 us slots take 12.9 ms: 100 Hz frames cannot hold them.
        table = "".join(f"{i:02X}80" for i in range(128))
        assert ask(link, f"LEDT:{table}") == "OKAY"
        assert ask(link, "RATE:100000") == "OKAY"
        assert ask(link, "START:") == ERROR_OUT_OF_RANGE

    def test_time_probe_ticks_are_ordered(self, link: serial.Serial) -> None:
        first = ask(link, "TIME:").split()
        second = ask(link, "TIME:").split()
        rx1, tx1 = int(first[1], 16), int(first[2], 16)
        rx2 = int(second[1], 16)
        assert first[0] == "TIME"
        assert tx1 >= rx1
        assert (rx2 - tx1) % 2**32 < 2_000_000  # less than 2 s between the two probes

    # -- streaming through the driver ---------------------------------------
    def test_driver_streams_every_frame_in_order(self, selspot_port: str) -> None:
        driver = SelspotDriver(selspot_port, cameras=1, leds=8, rate_hz=100.0, baud=115_200)
        with driver:
            blocks = []
            got = 0
            while got < 60:
                block = driver.recv(timeout=2.0)
                assert block is not None, "no frames within 2 s"
                blocks.append(block)
                got += len(block)
        seq = np.concatenate([b.seq for b in blocks])
        ticks = np.concatenate([b.ticks for b in blocks])
        assert np.all(np.diff(seq) == 1), "sequence numbers not contiguous"
        period_us = np.diff(ticks)
        assert abs(np.median(period_us) - 10_000) < 100, "frame period is not 10 ms"
        assert driver.stats.crc_errors == 0 and driver.stats.lost_frames == 0
        data = np.concatenate([b.data for b in blocks])
        assert data.shape[1:] == (8, 1, 3)
        assert driver.spec.slot_period_s == pytest.approx(100e-6)

    def test_configuration_while_streaming_is_refused(self, selspot_port: str) -> None:
        driver = SelspotDriver(selspot_port, cameras=1, leds=4, rate_hz=50.0, baud=115_200)
        with driver:
            assert driver.recv(timeout=2.0) is not None
            with pytest.raises(DeviceError) as info:
                driver.command("CAMS:2")
            assert info.value.code == 0x0C
