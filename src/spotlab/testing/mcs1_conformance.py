"""One conformance suite for every MCS-1 family (docs/protocols/mcs1.md and the family's spec).

The same tests run against the family's simulator in CI and against a real
device on a bench (``pytest tests/conformance --hw selspot=/dev/ttyUSB0``). A
family is described once by an :class:`Mcs1Family` (its name and code, how to
start its simulator, its driver, what its ``VER:0`` reply, its parameter checks
and its frames look like); a test class derives from :class:`Mcs1Conformance`,
sets ``family`` and adds only the family's own extra tests. The suite provides
the ``device_port`` fixture (the simulator on a pseudo-terminal and as a
``sim://`` URL, or the ``--hw`` port); a subclass may override it. The tests
configure small, safe set-ups and leave the device stopped and reset.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar, Protocol

import numpy as np
import pytest
import serial

from spotlab.core.errors import DeviceError
from spotlab.core.frames import FrameBlock
from spotlab.drivers.mcs1.driver import Mcs1Driver
from spotlab.testing.pytest_plugin import hardware_ports
from spotlab.testing.wire import BANNER, ask, check_reply, command, read_until, reset

#: Device code of ``ERRORxx`` "not allowed in this mode" (a configuration while streaming).
NOT_IN_THIS_MODE = 0x0C


class SimulatorServer(Protocol):
    """A simulator serving a pseudo-terminal: its path, and how to stop it."""

    @property
    def path(self) -> Path | str:
        """The pseudo-terminal to open."""

    def stop(self) -> None:
        """Stop serving."""


def _no_check(driver: Any, blocks: list[FrameBlock]) -> None:
    """No family-specific check of the streamed blocks."""


@dataclass(frozen=True)
class Mcs1Family:
    """What the shared suite needs to know of one MCS-1 family.

    Attributes
    ----------
    name : str
        Family name (``"selspot"``), the ``--hw`` key.
    code : str
        Family code opening the ``VER:0`` reply (``"SPX"``).
    driver : callable
        The driver class; called as ``driver(port, **stream)``.
    serve_pty : callable
        Starts the family's simulator on a pseudo-terminal.
    sim_url : callable
        The ``sim://`` URL of the same simulator.
    version_words : int
        Words of the ``VER:0`` reply.
    version_ranges : mapping of int to (float, float)
        Word index -> inclusive range of its number (``math.inf`` for no bound).
    rejected : sequence of (str, str)
        Out-of-range and malformed commands with the error reply each gets, in order.
    accepted : sequence of str
        Configuration commands the device answers ``OKAY``.
    bandwidth : sequence of (str, str)
        Commands and replies, in order, ending with ``START:`` refused for bandwidth.
    stream : mapping
        Driver keywords of the streaming test.
    frames : int
        Frames the streaming test collects.
    period_ticks, period_tolerance : float
        The frame period in the stream's ticks and the allowed error of its median.
    frame_shape : tuple of int or None
        ``FrameBlock.data.shape[1:]`` of the streaming test; None where it varies.
    refused_while_streaming : str
        A configuration command the device refuses while streaming (``ERROR0C``).
    while_streaming : sequence of str
        Commands the streaming test sends once the stream runs.
    check_stream : callable
        ``(driver, blocks)``: the family's own checks of what was streamed.
    """

    name: str
    code: str
    driver: Callable[..., Mcs1Driver]
    serve_pty: Callable[[], SimulatorServer]
    sim_url: Callable[[], str]
    version_words: int
    version_ranges: Mapping[int, tuple[float, float]]
    rejected: Sequence[tuple[str, str]]
    accepted: Sequence[str]
    bandwidth: Sequence[tuple[str, str]]
    stream: Mapping[str, Any]
    frames: int
    period_ticks: float
    period_tolerance: float
    frame_shape: tuple[int | None, ...]
    refused_while_streaming: str
    while_streaming: Sequence[str] = ()
    check_stream: Callable[[Any, list[FrameBlock]], None] = field(default=_no_check)


def collect(driver: Mcs1Driver, frames: int, timeout_s: float = 2.0) -> list[FrameBlock]:
    """Blocks from ``driver`` until they hold ``frames`` frames; fails if one wait times out."""
    blocks: list[FrameBlock] = []
    while sum(len(b) for b in blocks) < frames:
        block = driver.recv(timeout=timeout_s)
        assert block is not None, f"no {driver.family} frames within {timeout_s:g} s"
        blocks.append(block)
    return blocks


def exchange(link: serial.Serial, script: Sequence[tuple[str, str]]) -> None:
    """Send each command of ``script`` and check the reply it gets."""
    for text, expected in script:
        assert ask(link, text) == expected, text


class Mcs1Conformance:
    """Tests every MCS-1 device must pass; a subclass sets ``family``."""

    family: ClassVar[Mcs1Family]

    @pytest.fixture(params=["pty", "sim-url"])
    def device_port(self, request: pytest.FixtureRequest) -> Iterator[str]:
        """The ``--hw`` port of the family, else its simulator (pseudo-terminal, URL)."""
        hw = hardware_ports(request.config).get(self.family.name)
        if hw is not None:
            if request.param != "pty":
                pytest.skip("hardware run: one port only")
            yield hw
            return
        if request.param == "sim-url":
            yield self.family.sim_url()
            return
        server = self.family.serve_pty()
        try:
            yield str(server.path)
        finally:
            server.stop()

    @pytest.fixture
    def link(self, device_port: str) -> Iterator[serial.Serial]:
        """The device reset, at 9600 baud; stopped and reset afterwards."""
        port = serial.serial_for_url(device_port, baudrate=9600, timeout=0.05)
        try:
            reset(port)
            yield port
        finally:
            try:
                port.write(command("STOP:"))
                port.write(command("RESET:"))
                port.flush()
                # Wait for the banner: a device that is its own process (a simulator on a
                # pty) would otherwise send it to the next test's port as a stale reply.
                read_until(port, BANNER, 1.0)
            finally:
                port.close()

    # -- command layer (MCS-1 §3) ------------------------------------------------------
    def test_version_reply_names_the_family(self, link: serial.Serial) -> None:
        fields = ask(link, "VER:0").split()
        assert fields[0] == self.family.code, fields
        assert len(fields) == self.family.version_words, fields
        for index, (low, high) in self.family.version_ranges.items():
            assert low <= int(fields[index]) <= high, (index, fields)

    def test_unknown_command_is_error_01(self, link: serial.Serial) -> None:
        assert ask(link, "BOGUS:1") == "ERROR01"

    def test_bad_crc_is_error_04(self, link: serial.Serial) -> None:
        link.write(b"VER:00000\r")
        assert check_reply(read_until(link, b"\r", 1.0)) == "ERROR04"

    def test_space_form_needs_no_crc(self, link: serial.Serial) -> None:
        link.write(b"VER 0\r")
        assert check_reply(read_until(link, b"\r", 1.0)).startswith(self.family.code + " ")

    def test_time_probe_ticks_are_ordered(self, link: serial.Serial) -> None:
        first = ask(link, "TIME:").split()
        second = ask(link, "TIME:").split()
        rx1, tx1 = int(first[1], 16), int(first[2], 16)
        rx2 = int(second[1], 16)
        assert first[0] == "TIME"
        assert tx1 >= rx1
        assert (rx2 - tx1) % 2**32 < 2_000_000  # less than 2 s between the two probes

    # -- the family's parameters -------------------------------------------------------
    def test_out_of_range_and_malformed_parameters(self, link: serial.Serial) -> None:
        exchange(link, self.family.rejected)

    def test_configuration_commands_are_accepted(self, link: serial.Serial) -> None:
        exchange(link, [(text, "OKAY") for text in self.family.accepted])

    def test_bandwidth_is_checked_at_start(self, link: serial.Serial) -> None:
        assert self.family.bandwidth[-1] == ("START:", "ERROR80")
        exchange(link, self.family.bandwidth)

    # -- streaming through the driver --------------------------------------------------
    def test_driver_streams_every_frame_in_order(self, device_port: str) -> None:
        family = self.family
        driver = family.driver(device_port, **family.stream)
        with driver:
            for text in family.while_streaming:
                driver.command(text)
            blocks = collect(driver, family.frames)
            with pytest.raises(DeviceError) as info:
                driver.command(family.refused_while_streaming)
            assert info.value.code == NOT_IN_THIS_MODE
        seq = np.concatenate([b.seq for b in blocks])
        ticks = np.concatenate([b.ticks for b in blocks])
        assert np.all(np.diff(seq) == 1), "sequence numbers not contiguous"
        period = float(np.median(np.diff(ticks)))
        assert abs(period - family.period_ticks) < family.period_tolerance, period
        for block in blocks:
            shape = block.data.shape[1:]
            assert len(shape) == len(family.frame_shape), shape
            pairs = zip(family.frame_shape, shape, strict=True)
            assert all(want is None or want == n for want, n in pairs), shape
        assert driver.stats.crc_errors == 0 and driver.stats.lost_frames == 0
        family.check_stream(driver, blocks)


__all__ = ["Mcs1Conformance", "Mcs1Family", "collect", "exchange"]
