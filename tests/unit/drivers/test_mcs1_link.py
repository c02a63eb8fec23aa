"""Serial link: clear open errors, taps and arrival stamps, disconnection on a real pty."""

from __future__ import annotations

import os
import re
import threading
import time
import tty
from collections.abc import Iterator
from pathlib import Path

import pytest
import serial
from _spx_wire import line

from spotlab.core.errors import (
    ConfigurationError,
    DeviceDisconnected,
    DeviceError,
    DeviceNotFound,
    DeviceTimeout,
    ProtocolError,
)
from spotlab.drivers.mcs1.link import SerialLink, open_error
from spotlab.drivers.mcs1.session import CommandChannel


@pytest.fixture
def pty_pair() -> Iterator[tuple[int, str]]:
    master, slave = os.openpty()
    tty.setraw(slave)
    try:
        yield master, os.ttyname(slave)
    finally:
        for fd in (master, slave):
            try:
                os.close(fd)
            except OSError:
                pass


def test_missing_port_is_device_not_found_naming_it(tmp_path: Path) -> None:
    path = str(tmp_path / "ttyUSB9")
    with pytest.raises(DeviceNotFound, match="ttyUSB9"):
        SerialLink(path).open()


def test_permission_denied_says_how_to_fix_it(monkeypatch: pytest.MonkeyPatch) -> None:
    class Denied:
        baudrate = timeout = write_timeout = exclusive = None

        def open(self) -> None:
            raise serial.SerialException(13, "could not open port /dev/ttyUSB0: [Errno 13]")

    monkeypatch.setattr(serial, "serial_for_url", lambda *a, **k: Denied())
    with pytest.raises(DeviceError) as info:
        SerialLink("/dev/ttyUSB0").open()
    message = str(info.value)
    assert "permission denied" in message and "dialout" in message and "udev" in message
    assert not isinstance(info.value, DeviceNotFound)


def test_unknown_url_scheme_is_a_configuration_error() -> None:
    with pytest.raises(ConfigurationError, match="nosuch://"):
        SerialLink("nosuch://x").open()
    hint = open_error("sim://selspot", ValueError("invalid URL, protocol 'sim' not known"))
    assert "spotlab.simulators" in str(hint)


def test_refused_socket_is_device_not_found() -> None:
    with pytest.raises(DeviceNotFound, match=re.escape("socket://127.0.0.1:9")):
        SerialLink("socket://127.0.0.1:9").open()


def test_port_in_use_is_named(pty_pair: tuple[int, str]) -> None:
    _, path = pty_pair
    first = SerialLink(path)
    first.open()
    try:
        with pytest.raises(DeviceError, match="in use by another program"):
            SerialLink(path).open()
    finally:
        first.close()


def test_read_write_taps_and_stamps(pty_pair: tuple[int, str]) -> None:
    master, path = pty_pair
    rx: list[tuple[bytes, int]] = []
    tx: list[bytes] = []
    link = SerialLink(path, on_rx=lambda d, t: rx.append((d, t)), on_tx=lambda d, t: tx.append(d))
    link.open(9600)
    try:
        assert link.is_open and link.baud == 9600
        link.set_baud(2_000_000)
        assert link.baud == 2_000_000
        link.write(b"VER:0F7C1\r")
        assert os.read(master, 100) == b"VER:0F7C1\r"
        assert tx == [b"VER:0F7C1\r"]
        assert link.read(0.01)[0] == b""
        os.write(master, b"OKAY26CF\r\xa5\x5a")
        before = time.monotonic_ns()
        data, t_ns = link.read_line(time.monotonic() + 1)
        assert data == b"OKAY26CF\r" and t_ns >= before - 10**9
        rest, _ = link.read(1.0)
        assert rest == b"\xa5\x5a"  # nothing after the CR was taken by read_line
        assert [d for d, _ in rx] == [b"OKAY26CF\r", b"\xa5\x5a"]
        assert link.send_break() in (True, False)
    finally:
        link.close()
    link.close()  # twice is fine
    assert not link.is_open


def test_disconnection_during_use(pty_pair: tuple[int, str]) -> None:
    master, path = pty_pair
    link = SerialLink(path)
    link.open()
    try:
        os.close(master)
        with pytest.raises(DeviceDisconnected, match="went away"):
            link.read(0.5)
        with pytest.raises(DeviceDisconnected):
            link.write(b"x" * 10)
    finally:
        link.close()
    with pytest.raises(DeviceDisconnected, match="not open"):
        link.read(0.1)


def test_channel_skips_noise_and_finds_replies(pty_pair: tuple[int, str]) -> None:
    master, path = pty_pair
    link = SerialLink(path)
    link.open()
    try:
        channel = CommandChannel(link, reply_timeout=0.3)
        os.write(master, b"AT\r" + b"xx" + line("OKAY"))
        assert channel.read_reply("CAMS:1").kind == "okay"
        assert channel.stats.crc_errors == 1
        os.write(master, b"garbage\r")
        with pytest.raises(ProtocolError, match="damaged lines: b'garbage"):
            channel.read_reply("CAMS:1")
        with pytest.raises(DeviceTimeout, match="no reply to CAMS:1"):
            channel.read_reply("CAMS:1")
        os.write(master, b"RESET7DB2\r")
        with pytest.raises(ProtocolError, match="reset itself"):
            channel.read_reply("SLOT:100")
    finally:
        link.close()


def test_a_reply_under_way_at_the_deadline_gets_time_to_end(pty_pair: tuple[int, str]) -> None:
    """A reply cut by a stall longer than the reply timeout (a starved device or host):
    the line that had begun is given the timeout once more; a second stall is an error."""
    master, path = pty_pair
    link = SerialLink(path)
    link.open()
    try:
        channel = CommandChannel(link, reply_timeout=0.3)
        reply = line("OKAY")
        os.write(master, reply[:4])
        t0 = time.monotonic()
        threading.Timer(0.45, os.write, (master, reply[4:])).start()
        assert channel.read_reply("START:").kind == "okay"
        assert 0.4 < time.monotonic() - t0 < 0.6 and channel.stats.crc_errors == 0
        os.write(master, reply[:4])  # and the rest never comes
        with pytest.raises(ProtocolError, match="damaged lines: b'OKAY'"):
            channel.read_reply("START:")
    finally:
        link.close()
