"""sim:// through serial.serial_for_url, a real pseudo-terminal with plain pyserial, TCP via socket://."""

from __future__ import annotations

import csv
import json
import os
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
import serial
from _simwire import cmd, decode, reply_text, spx

import spotlab.simulators  # noqa: F401 - registers sim://
from spotlab.simulators.service import SelspotSimOptions, serve_pty, serve_tcp

BANNER = b"RESET7DB2\r"


def read_until(port: serial.SerialBase, end: bytes, timeout: float = 2.0) -> bytes:
    """Bytes up to and including ``end`` (byte by byte: nothing after it is consumed)."""
    deadline = time.monotonic() + timeout
    out = bytearray()
    while time.monotonic() < deadline and not out.endswith(end):
        out += port.read(1)
    return bytes(out)


def resync_line(port: serial.SerialBase) -> None:
    """After talking at the wrong rate: end whatever garbage the device holds, drop replies."""
    port.write(b"\r")
    time.sleep(0.05)
    port.reset_input_buffer()


def ask(port: serial.SerialBase, text: str) -> str:
    port.write(cmd(text))
    return reply_text(read_until(port, b"\r"))


def negotiate(port: serial.SerialBase, baud_code: int = 8, baud: int = 2_000_000) -> None:
    time.sleep(0.03)  # let a power-up banner finish, then start clean
    port.reset_input_buffer()
    port.write(cmd("RESET:"))
    assert read_until(port, BANNER).endswith(BANNER)
    assert ask(port, f"COMM:{baud_code}") == "OKAY"
    port.baudrate = baud
    assert ask(port, "VER:0").startswith("SPX 1.0")


def configure(
    port: serial.SerialBase, cams: int = 2, leds: int = 4, rate_mhz: int = 100_000
) -> None:
    table = "".join(f"{i:02X}80" for i in range(leds))
    for text in (f"CAMS:{cams}", f"LEDT:{table}", f"RATE:{rate_mhz}"):
        assert ask(port, text) == "OKAY", text
    port.write(cmd("START:"))
    assert read_until(port, b"\r") == b"OKAY26CF\r"


def collect(port: serial.SerialBase, seconds: float) -> bytes:
    out = bytearray()
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        out += port.read(4096)
    return bytes(out)


def data_frames(raw: bytes) -> list[dict[str, object]]:
    got = decode(raw)
    return [spx(f["payload"]) | {"seq": f["seq"]} for f in got.frames if f["type"] == 1]  # type: ignore[arg-type]


@pytest.fixture
def sim_port(tmp_path: Path) -> Iterator[serial.SerialBase]:
    files = f"truth={tmp_path / 't.csv'}&fault_log={tmp_path / 'f.json'}"
    url = f"sim://selspot?cameras=2&leds=4&seed=3&{files}"
    port = serial.serial_for_url(url, timeout=0.05)
    try:
        yield port
    finally:
        port.close()


def test_sim_url_streams_through_serial_for_url(
    sim_port: serial.SerialBase, tmp_path: Path
) -> None:
    assert type(sim_port).__module__ == "spotlab.simulators.transports.protocol_sim"
    assert sim_port.in_waiting == 0  # powered up before the port opened: nothing stale
    negotiate(sim_port)
    configure(sim_port)
    frames = data_frames(collect(sim_port, 0.3))
    assert len(frames) >= 20
    assert [f["seq"] for f in frames] == list(range(len(frames)))
    ticks = np.array([f["tick"] for f in frames])
    assert np.all(np.abs(np.diff(ticks) - 10_000) <= 1)
    sim_port.write(cmd("STOP:"))
    sim_port.flush()
    collect(sim_port, 0.05)
    sim_port.close()
    rows = list(csv.DictReader((tmp_path / "t.csv").read_text().splitlines()))
    assert len(rows) >= len(frames)
    assert json.loads((tmp_path / "f.json").read_text())["totals"]["frames_sent"] >= len(frames)


def test_sim_url_wrong_baud_reads_garbage(sim_port: serial.SerialBase) -> None:
    sim_port.write(cmd("COMM:5"))
    assert read_until(sim_port, b"OKAY26CF\r").endswith(b"OKAY26CF\r")
    sim_port.write(cmd("VER:0"))  # the port stays at 9600, the device now runs at 115200
    got = collect(sim_port, 0.3)
    assert b"SPX" not in got
    sim_port.baudrate = 115_200
    resync_line(sim_port)
    assert ask(sim_port, "VER:0").startswith("SPX")


def test_sim_url_break_resets(sim_port: serial.SerialBase) -> None:
    negotiate(sim_port, baud_code=6, baud=921_600)
    sim_port.baudrate = 9600  # the banner comes at 9600: listen there first
    sim_port.send_break(0.01)
    assert read_until(sim_port, BANNER).endswith(BANNER)
    assert ask(sim_port, "LEDQ:") == "ERROR82"


def test_sim_url_timeouts(sim_port: serial.SerialBase) -> None:
    sim_port.timeout = 0
    assert sim_port.read(10) == b""
    assert sim_port.in_waiting == 0
    sim_port.timeout = 0.05
    t0 = time.monotonic()
    assert sim_port.read(10) == b""
    assert time.monotonic() - t0 >= 0.05


def test_sim_url_rejects_bad_options() -> None:
    with pytest.raises(serial.SerialException, match="unknown option"):
        serial.serial_for_url("sim://selspot?cameras=2&bogus=1")
    with pytest.raises(serial.SerialException, match="cameras"):
        serial.serial_for_url("sim://selspot?cameras=9")
    with pytest.raises(serial.SerialException, match="selspot"):
        serial.serial_for_url("sim://linear")  # no such family (coda is one since issue 18)


def test_sim_url_disconnect_and_reopen() -> None:
    port = serial.serial_for_url(
        "sim://selspot?cameras=1&leds=4&faults=disconnect@0.2:0.4", timeout=0.05
    )
    try:
        negotiate(port)
        configure(port, cams=1)
        before = data_frames(collect(port, 0.1))
        with pytest.raises(serial.SerialException):
            collect(port, 1.0)
        with pytest.raises(serial.SerialException):
            port.write(cmd("STAT:"))
        port.close()
        with pytest.raises(serial.SerialException, match="disconnected"):
            port.open()
        deadline = time.monotonic() + 2.0
        while not port.is_open and time.monotonic() < deadline:
            try:
                port.open()
            except serial.SerialException:
                time.sleep(0.02)
        assert port.is_open and port.baudrate == 2_000_000
        after = data_frames(collect(port, 0.2))
        assert after and int(after[0]["seq"]) > int(before[-1]["seq"]) + 20  # type: ignore[call-overload]
    finally:
        port.close()


def test_pty_session_with_plain_pyserial(tmp_path: Path) -> None:
    options = SelspotSimOptions(cameras=2, leds=4, truth=tmp_path / "t.csv")
    server = serve_pty(options)
    port = None
    try:
        assert server.path.is_symlink() and os.readlink(server.path).startswith("/dev/pts/")
        port = serial.Serial(str(server.path), 9600, timeout=0.05)
        negotiate(port)  # RESET: -> banner, COMM:8 through the real termios path
        configure(port)
        frames = data_frames(collect(port, 0.3))
        assert len(frames) >= 20 and [f["seq"] for f in frames] == list(range(len(frames)))
        assert all(f["n_cams"] == 2 and f["n_leds"] == 4 for f in frames)
        port.write(cmd("STOP:"))
        collect(port, 0.05)
    finally:
        if port is not None:
            port.close()
        server.stop()
    assert not server.path.parent.exists()


def test_pty_baud_mismatch_garbles(tmp_path: Path) -> None:
    with serve_pty(SelspotSimOptions(cameras=1, leds=2)) as server:
        port = serial.Serial(str(server.path), 9600, timeout=0.05)
        try:
            time.sleep(0.03)
            port.reset_input_buffer()
            port.write(cmd("COMM:5"))
            assert read_until(port, b"OKAY26CF\r").endswith(b"OKAY26CF\r")
            port.write(cmd("VER:0"))  # still 9600 on the host side
            assert b"SPX" not in collect(port, 0.3)
            port.baudrate = 115_200
            resync_line(port)
            assert ask(port, "VER:0").startswith("SPX")
        finally:
            port.close()


def test_pty_disconnect_and_return_on_the_same_path() -> None:
    options = SelspotSimOptions(cameras=1, leds=4, faults="disconnect@0.2:0.5")
    with serve_pty(options) as server:
        first_pts = os.readlink(server.path)
        port = serial.Serial(str(server.path), 9600, timeout=0.05)
        try:
            negotiate(port)
            configure(port, cams=1)
            before = data_frames(collect(port, 0.1))
            with pytest.raises(serial.SerialException):
                collect(port, 1.0)  # EIO once the master is gone
            port.close()
            deadline = time.monotonic() + 3.0
            while not server.path.exists() and time.monotonic() < deadline:
                time.sleep(0.02)
            assert server.path.exists()
            assert server.stats["reconnects"] == 1
            port = serial.Serial(str(server.path), 2_000_000, timeout=0.05)
            after = data_frames(collect(port, 0.2))
            assert after and int(after[-1]["seq"]) > int(before[-1]["seq"]) + 30  # type: ignore[call-overload]
        finally:
            port.close()
    assert first_pts.startswith("/dev/pts/")


def test_tcp_socket_url() -> None:
    with serve_tcp(SelspotSimOptions(cameras=2, leds=4)) as server:
        assert server.url.startswith("socket://127.0.0.1:")
        port = serial.serial_for_url(server.url, timeout=0.05)
        try:
            port.write(cmd("RESET:"))
            assert read_until(port, BANNER).endswith(BANNER)
            assert ask(port, "COMM:8") == "OKAY"  # no baud on TCP: nothing to switch
            configure(port)
            frames = data_frames(collect(port, 0.3))
            assert len(frames) >= 20 and [f["seq"] for f in frames] == list(range(len(frames)))
            port.write(cmd("STOP:"))
            collect(port, 0.05)
        finally:
            port.close()
        second = serial.serial_for_url(server.url, timeout=0.05)  # the next client picks it up
        try:
            assert ask(second, "VER:0").startswith("SPX")
        finally:
            second.close()


def test_a_sim_device_too_slow_for_real_time_runs_its_clock_slow(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """A hub whose frames take 10 ms each to render at 300 Hz (a host too busy for it):
    reads catch it up 10 ms at a time, so a recording ends on time with fewer frames and
    none lost, instead of each read rendering every frame due since the last, ever later."""
    from spotlab.acquisition.recorder import Recorder
    from spotlab.acquisition.replay import replay
    from spotlab.acquisition.session import Session
    from spotlab.drivers.centroid import CentroidDriver
    from spotlab.processing.decoding import decoder_for
    from spotlab.simulators.centroid import CentroidStream
    from spotlab.simulators.centroid_service import CentroidSimOptions, centroid_url_for

    take = CentroidStream.take

    def slow_take(self: CentroidStream) -> object:
        time.sleep(0.01)
        return take(self)

    monkeypatch.setattr(CentroidStream, "take", slow_take)
    options = CentroidSimOptions(cameras=2, markers=6, rate_hz=300, seed=1)
    driver = CentroidDriver(centroid_url_for(options), cameras=2, rate_hz=300)
    journal = tmp_path / "slow.spj"
    t0 = time.monotonic()
    with Session([driver], [Recorder(journal, {})], close_devices=True) as session:
        session.run_for(1.0)
    took = time.monotonic() - t0
    blocks = [b for _, b in replay(journal, decoder_for) if len(b)]
    seq = np.concatenate([b.seq for b in blocks]) if blocks else np.zeros(0, np.int64)
    print(f"{len(seq)} frames in {took:.2f} s, lost {driver.stats.lost_frames}")
    assert took < 6.0
    assert 20 <= len(seq) < 200  # at most 100 frames a second rendered, not 300
    assert np.all(np.diff(seq) == 1) and driver.stats.lost_frames == 0
