"""Conformance suite of the timer/sync (TMR) family (docs/protocols/timer.md).

Runs against the simulator in CI and against a real unit on a bench
(``pytest tests/conformance --hw timer=/dev/ttyUSB1``). Subclass
:class:`TimerConformance` and provide a ``timer_port`` fixture that yields a
device path or pyserial URL. The tests leave the unit stopped and reset.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest
import serial

from spotlab.core.errors import DeviceError
from spotlab.core.frames import FrameBlock
from spotlab.drivers.timer import TimerDriver, extract_edges
from spotlab.testing.wire import ask, reset
from spotlab.testing.wire import command as wire_command


class TimerConformance:
    """Tests every TMR unit must pass. Needs a ``timer_port`` fixture."""

    @pytest.fixture
    def link(self, timer_port: str) -> Iterator[serial.Serial]:
        port = serial.serial_for_url(timer_port, baudrate=9600, timeout=0.05)
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

    def test_version_reply_names_the_family_and_counter(self, link: serial.Serial) -> None:
        fields = ask(link, "VER:0").split()
        assert fields[0] == "TMR" and len(fields) == 6, fields
        assert int(fields[3]) >= 1 and int(fields[5]) == 10_000_000

    def test_out_of_range_and_malformed_parameters(self, link: serial.Serial) -> None:
        assert ask(link, "EDGS:0") == "ERROR23"
        assert ask(link, "RATE:999") == "ERROR23"
        assert ask(link, "ARM:9,1") == "ERROR23"
        assert ask(link, "ARM:0,4") == "ERROR23"
        assert ask(link, "ARM:0") == "ERROR07"
        assert ask(link, "TCOD:1,25,1") == "ERROR23"  # drop-frame only at 30
        assert ask(link, "BOGUS:1") == "ERROR01"

    def test_configuration_commands_are_accepted(self, link: serial.Serial) -> None:
        for text in ("RATE:250000", "EDGS:4", "ARM:0,3", "TCOD:1,30,1", "POUT:0,1000", "TCOD:0"):
            assert ask(link, text) == "OKAY", text

    def test_pulse_reply_carries_a_counter_on_a_whole_microsecond(
        self, link: serial.Serial
    ) -> None:
        a = int(ask(link, "PULS:0").split()[1], 16)
        b = int(ask(link, "PULS:0").split()[1], 16)
        assert a % 10 == 0 and b % 10 == 0
        assert 0 < b - a < 20_000_000  # less than 2 s between the two

    def test_bandwidth_is_checked_at_start(self, link: serial.Serial) -> None:
        assert ask(link, "START:") == "ERROR80"  # 140-byte frames at 100 Hz need > 9600 baud

    def test_driver_streams_frames_with_periodic_output_pulses(self, timer_port: str) -> None:
        driver = TimerDriver(timer_port, rate_hz=100.0, slots=4, timecode=(25, False))
        with driver:
            driver.command("POUT:2,5000")  # a pulse every 5 ms on output 2
            blocks: list[FrameBlock] = []
            while sum(len(b) for b in blocks) < 60:
                block = driver.recv(timeout=2.0)
                assert block is not None, "no timer frames within 2 s"
                blocks.append(block)
            with pytest.raises(DeviceError) as info:
                driver.command("EDGS:2")
            assert info.value.code == 0x0C
        edges = extract_edges(blocks)
        assert np.all(np.diff(edges.frame_seqs) == 1)
        assert abs(np.median(np.diff(edges.frame_ticks)) - 100_000) < 100
        pulses = edges.select(0x80 | 2)
        assert len(pulses) >= 100
        assert np.all(pulses.tick % 50_000 == 0)
        assert np.all(np.diff(pulses.tick) == 50_000)
        tc = np.concatenate([b.data[:, -1, 0, :] for b in blocks])
        assert np.all(tc[:, 2] == 25) and np.all(tc[:, 1] < 25)
        assert driver.stats.crc_errors == 0 and driver.stats.lost_frames == 0
