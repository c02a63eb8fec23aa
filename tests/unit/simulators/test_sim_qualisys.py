"""The simulated QTM server against docs/protocols/qualisys.md: golden vectors, commands,
parameters, streaming, control, faults and truth (raw sockets, no client library)."""

from __future__ import annotations

import socket
import struct
import time
import xml.etree.ElementTree as ET
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from spotlab.simulators import qualisys_wire as qw
from spotlab.simulators.qualisys import QualisysServer, QualisysSimOptions
from spotlab.testing.golden import golden_vector

SPEC = Path(__file__).parents[3] / "docs" / "protocols" / "qualisys.md"


def golden(name: str) -> bytes:
    """The bytes of golden vector ``name`` (``G1``...) as the spec writes them."""
    return golden_vector(SPEC, name)


def test_golden_replies_are_what_the_server_writes() -> None:
    assert qw.text_packet(qw.COMMAND, "Version set to 1.25") == golden("G2")
    assert qw.text_packet(qw.COMMAND, "QTM RT Interface connected") == golden("G3")
    xml = (
        "<QTM_Parameters_Ver_1.25><The_3D><Labels>2</Labels><Label><Name>LASI</Name></Label>"
        "<Label><Name>RASI</Name></Label></The_3D></QTM_Parameters_Ver_1.25>"
    )
    assert qw.text_packet(qw.XML, xml) == golden("G5")
    markers = np.array([[100.5, -20.25, 950.0], [np.nan, np.nan, np.nan]])
    assert qw.data_packet(1_230_000, 124, [qw.component_3d(markers)]) == golden("G6")
    six = qw.component_6d(np.array([[10.0, 20.0, 30.0]]), np.eye(3)[None])
    assert qw.data_packet(10_000, 2, [six]) == golden("G7")
    assert qw.event_packet(qw.EV_CAPTURE_STARTED) == golden("G8")
    assert qw.packet(qw.NO_MORE_DATA, b"") == golden("G9")
    assert qw.text_packet(qw.ERROR, "Version NOT supported") == golden("G10")


def test_golden_commands_are_read_from_any_split() -> None:
    stream = golden("G1") + golden("G4") + golden("G11")
    reader = qw.CommandReader()
    got = [p for i in range(len(stream)) for p in reader.feed(stream[i : i + 1])]
    assert [(p.kind, p.text) for p in got] == [
        (qw.COMMAND, "Version 1.25"),
        (qw.COMMAND, "GetParameters 3D"),
        (qw.COMMAND, "StreamFrames AllFrames 3D 6D"),
    ]


def test_golden_udp_stream_command_sends_datagrams_there() -> None:
    """G12 asks for the frames by UDP at port 7777 of the address the command came from."""
    with QualisysServer(QualisysSimOptions(markers=4, rate_hz=100.0)) as server:
        peer = Peer(server.port)
        peer.packet()  # the welcome
        peer.sock.sendall(golden("G12"))
        t_end = time.monotonic() + 2.0
        while not any(c.divisor for c in server._clients) and time.monotonic() < t_end:
            time.sleep(0.01)
        (client,) = server._clients
        assert client.udp == ("127.0.0.1", 7777) and client.components == ("3d", "6d")
        peer.sock.close()


def test_6d_rotation_is_sent_column_by_column() -> None:
    r = np.arange(9.0).reshape(1, 3, 3)
    body = qw.component_6d(np.zeros((1, 3)), r)
    floats = struct.unpack_from("<12f", body, 16)
    assert floats[3:] == (0.0, 3.0, 6.0, 1.0, 4.0, 7.0, 2.0, 5.0, 8.0)


class Peer:
    """A raw TCP client of the simulator: sends commands, reads packets."""

    def __init__(self, port: int) -> None:
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=5)
        self.buf = b""

    def send(self, text: str) -> None:
        self.sock.sendall(qw.text_packet(qw.COMMAND, text))

    def packet(self) -> tuple[int, bytes]:
        while True:
            if len(self.buf) >= 8:
                size, kind = struct.unpack_from("<II", self.buf)
                if len(self.buf) >= size:
                    body, self.buf = self.buf[8:size], self.buf[size:]
                    return kind, body
            data = self.sock.recv(65536)
            if not data:
                raise ConnectionError("closed")
            self.buf += data

    def text(self) -> tuple[int, str]:
        kind, body = self.packet()
        return kind, body.rstrip(b"\0").decode()

    def close(self) -> None:
        self.sock.close()


@pytest.fixture
def server() -> Iterator[QualisysServer]:
    with QualisysServer(QualisysSimOptions(markers=40, cameras=4, password="secret")) as s:
        yield s


def test_session_welcome_version_parameters(server: QualisysServer) -> None:
    peer = Peer(server.port)
    assert peer.text() == (qw.COMMAND, "QTM RT Interface connected")
    peer.sock.sendall(golden("G1"))
    kind, body = peer.packet()
    assert struct.pack("<II", 8 + len(body), kind) + body == golden("G2")
    peer.send("version 1.7")
    assert peer.text() == (qw.ERROR, "Version NOT supported")
    peer.send("Version")
    assert peer.text() == (qw.COMMAND, "Version is 1.25")
    peer.send("ByteOrder")
    assert peer.text() == (qw.COMMAND, "Byte order is little endian")
    peer.send("GetParameters All")
    kind, xml = peer.text()
    assert kind == qw.XML
    root = ET.fromstring(xml)
    assert root.tag == "QTM_Parameters_Ver_1.25"
    assert root.findtext("General/Frequency") == "100"
    assert len(root.findall("General/Camera")) == 4
    labels = [e.text for e in root.findall("The_3D/Label/Name")]
    assert labels == list(server.scene.labels) and len(labels) == 40
    assert root.findtext("The_3D/Labels") == "40"
    assert [e.text for e in root.findall("The_6D/Body/Name")] == ["pelvis", "head", "thorax"]
    peer.send("GetParameters 3D")
    root = ET.fromstring(peer.text()[1])
    assert root.find("General") is None and root.find("The_3D") is not None
    peer.send("Frobnicate")
    assert peer.text() == (qw.ERROR, "Parse error")
    peer.close()


def _data(body: bytes) -> tuple[int, int, dict[int, bytes]]:
    ts, frame, n = struct.unpack_from("<qII", body)
    comps, pos = {}, 16
    for _ in range(n):
        size, kind = struct.unpack_from("<II", body, pos)
        comps[kind] = body[pos + 8 : pos + size]
        pos += size
    assert pos == len(body)
    return ts, frame, comps


def test_stream_frames_3d_6d_match_the_truth(server: QualisysServer) -> None:
    peer = Peer(server.port)
    peer.text()
    peer.send("StreamFrames AllFrames 3D 6D 3DNoLabels 2D")
    frames = []
    for _ in range(30):
        kind, body = peer.packet()
        assert kind == qw.DATA
        frames.append(_data(body))
    peer.send("StreamFrames Stop")
    peer.close()
    server.stop()
    truth = server.truth()
    numbers = [f for _, f, _ in frames]
    assert numbers == list(range(numbers[0], numbers[0] + 30))
    for ts, n, comps in frames:
        i = int(np.flatnonzero(truth["frame"] == n)[0])
        assert ts == truth["timestamp_us"][i] == round((n - 1) * 1e4)
        count, _, _ = struct.unpack_from("<Ihh", comps[1])
        xyz = np.frombuffer(comps[1], "<f4", count * 3, 8).reshape(-1, 3)
        assert np.array_equal(xyz, truth["markers_mm"][i].astype(np.float32))
        nb, _, _ = struct.unpack_from("<ihh", comps[5])
        bodies = np.frombuffer(comps[5], "<f4", nb * 12, 8).reshape(nb, 12)
        assert np.array_equal(bodies[:, :3], truth["body_positions_mm"][i].astype(np.float32))
        rot = bodies[:, 3:].reshape(nb, 3, 3).transpose(0, 2, 1)
        assert np.allclose(rot, truth["body_rotations"][i], atol=1e-6)
        assert np.allclose(rot @ rot.transpose(0, 2, 1), np.eye(3), atol=1e-5)
        nl, _, _ = struct.unpack_from("<Ihh", comps[2])
        rec = np.frombuffer(comps[2], [("xyz", "<f4", 3), ("id", "<u4")], nl, 8)
        assert np.array_equal(rec["xyz"], xyz[rec["id"] - 1])
        ncam, _, _ = struct.unpack_from("<Ihh", comps[7])
        assert ncam == 4
    assert truth["labels"].tolist() == list(server.scene.labels)


def test_frequency_divisor_and_state_events(server: QualisysServer) -> None:
    peer = Peer(server.port)
    peer.text()
    peer.send("GetState")
    assert peer.packet() == (qw.EVENT, bytes([qw.EV_CONNECTED]))
    peer.send("StreamFrames Frequency:25 3D")
    numbers = [_data(peer.packet()[1])[1] for _ in range(5)]
    assert np.all(np.diff(numbers) == 4) and (numbers[0] - 1) % 4 == 0
    peer.send("StreamFrames Stop")
    peer.send("StreamFrames Bogus:3 3D")
    peer.send("StreamFrames AllFrames Analog")
    texts = []
    while len(texts) < 2:
        kind, body = peer.packet()
        if kind == qw.ERROR:
            texts.append(body.rstrip(b"\0").decode())
    assert texts[0].startswith("Parse error") and "analog" in texts[1]
    peer.close()


def test_take_control_password_and_capture_events(server: QualisysServer) -> None:
    a, b = Peer(server.port), Peer(server.port)
    a.text(), b.text()
    a.send("Start")
    assert a.text() == (qw.ERROR, "You must be master to issue this command")
    a.send("TakeControl wrong")
    assert a.text() == (qw.ERROR, "Wrong or missing password")
    a.send("TakeControl")
    assert a.text() == (qw.ERROR, "Wrong or missing password")
    a.send("TakeControl secret")
    assert a.text() == (qw.COMMAND, "You are now master")
    b.send("TakeControl secret")
    assert b.text() == (qw.ERROR, "The client is already master")
    a.send("Start")
    assert a.text() == (qw.COMMAND, "Starting measurement")
    assert a.packet() == (qw.EVENT, bytes([qw.EV_CAPTURE_STARTED]))
    assert b.packet() == (qw.EVENT, bytes([qw.EV_CAPTURE_STARTED]))
    a.send("Stop")
    assert a.text() == (qw.COMMAND, "Stopping measurement")
    assert a.packet() == (qw.EVENT, bytes([qw.EV_CAPTURE_STOPPED]))
    assert b.packet() == (qw.EVENT, bytes([qw.EV_CAPTURE_STOPPED]))
    a.send("ReleaseControl")
    assert a.text() == (qw.COMMAND, "You are now a regular client")
    b.send("TakeControl secret")
    assert b.text() == (qw.COMMAND, "You are now master")
    a.close(), b.close()


def test_drop_and_disconnect_faults(tmp_path: Path) -> None:
    options = QualisysSimOptions(
        markers=4, rate_hz=200.0, faults="drop@0.1:3,disconnect@0.3:0.2", truth=tmp_path / "t.npz"
    )
    with QualisysServer(options) as server:
        peer = Peer(server.port)
        peer.text()
        peer.send("StreamFrames AllFrames 3D")
        numbers, events = [], []
        with pytest.raises(ConnectionError):
            while True:
                kind, body = peer.packet()
                if kind == qw.DATA:
                    numbers.append(_data(body)[1])
                elif kind == qw.EVENT:
                    events.append(body[0])
        peer.close()
        assert events == [qw.EV_CONNECTION_CLOSED]
        gaps = np.flatnonzero(np.diff(numbers) != 1)
        assert len(gaps) == 1 and numbers[gaps[0] + 1] - numbers[gaps[0]] == 4
        assert 0.2 * 200 <= len(numbers) <= 0.6 * 200
        time.sleep(0.3)  # the outage is over: a client may come back
        again = Peer(server.port)
        assert again.text() == (qw.COMMAND, "QTM RT Interface connected")
        again.close()
    truth = np.load(tmp_path / "t.npz")
    assert set(numbers) <= set(truth["frame"].tolist())
    assert not {numbers[gaps[0]] + k for k in (1, 2, 3)} & set(truth["frame"].tolist())
    assert [e["kind"] for e in server.fault_log] == ["drop", "disconnect"]


def test_spotlab_sim_qualisys_command(tmp_path: Path) -> None:
    """First stdout line host:port on 127.0.0.1; SIGTERM stops it and writes the truth."""
    import os
    import signal
    import subprocess
    import sys

    truth = tmp_path / "t.npz"
    argv = [
        "sim",
        "qualisys",
        "--markers",
        "8",
        "--rate",
        "50",
        "--seed",
        "4",
        "--truth",
        str(truth),
    ]
    proc = subprocess.Popen(
        [sys.executable, "-m", "spotlab.console.cli", *argv],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONWARNINGS": "ignore"},
    )
    try:
        assert proc.stdout is not None
        host, port = proc.stdout.readline().strip().split(":")
        assert host == "127.0.0.1"
        peer = Peer(int(port))
        assert peer.text() == (qw.COMMAND, "QTM RT Interface connected")
        peer.send("StreamFrames AllFrames 3D")
        got = [_data(peer.packet()[1])[1] for _ in range(10)]
        peer.close()
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=20)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 0, err
    t = np.load(truth)
    assert set(got) <= set(t["frame"].tolist()) and t["markers_mm"].shape[1:] == (8, 3)
    assert np.allclose(t["time_s"], (t["frame"] - 1) / 50)
    assert t["labels"].tolist()[:2] == ["HEAD", "C7"]


def test_clock_drift_and_sync_output_in_the_lab(tmp_path: Path) -> None:
    """--clock-drift-ppm: timestamps run fast by that many ppm of the true capture times;
    --lab-name publishes the sync output's frame pulses at those true instants."""
    from spotlab.simulators.lab import PulseSource

    options = QualisysSimOptions(
        markers=4, rate_hz=200.0, clock_drift_ppm=500.0, lab=tmp_path, lab_name="qtm"
    )
    with QualisysServer(options) as server:
        peer = Peer(server.port)
        peer.text()
        peer.send("StreamFrames AllFrames 3D")
        frames = [_data(peer.packet()[1])[:2] for _ in range(40)]
        peer.close()
        source = PulseSource(tmp_path, "qtm")
        source.refresh()
        assert source.clock is not None and source.clock.drift_ppm == 500.0
        stream = source.streams[0]
        t0 = source.clock.epoch_ns
        rises = [p for p in source.pulses(stream, t0 - 1, t0 + 0.0975e9) if p.rising]
    for ts, n in frames:
        assert ts == round((n - 1) * 5000 * 1.0005)
    # frame n's pulse rises (n - 1) / 200 s after power-up (true time), within rounding
    assert len(rises) == 20
    k = np.array([p.frame_no for p in rises])
    assert np.array_equal(k, np.arange(20))
    np.testing.assert_allclose([p.world_ns - t0 for p in rises], k * 5e6, atol=1e3)
    with pytest.raises(ValueError, match="clock-drift-ppm"):
        QualisysSimOptions(clock_drift_ppm=2e4).validate()


def test_late_restart_and_slow_faults(tmp_path: Path) -> None:
    options = QualisysSimOptions(
        markers=4, rate_hz=200.0, faults="late@0.1:3,slow@0.2:4,restart@0.3,disconnect@0.5:0.2"
    )
    with QualisysServer(options) as server:
        peer = Peer(server.port)
        peer.text()
        peer.send("StreamFrames AllFrames 3D")
        got: list[tuple[int, float]] = []  # (frame number, arrival s)
        events: list[tuple[int, int]] = []  # (event, frames received before it)
        with pytest.raises(ConnectionError):
            while True:
                kind, body = peer.packet()
                if kind == qw.DATA:
                    got.append((_data(body)[1], time.monotonic()))
                elif kind == qw.EVENT:
                    events.append((body[0], len(got)))
        peer.close()
    numbers = [n for n, _ in got]
    assert [e for e, _ in events] == [
        qw.EV_CAPTURE_STOPPED, qw.EV_CAPTURE_STARTED, qw.EV_CONNECTION_CLOSED
    ]  # fmt: skip
    restart = events[1][1]
    assert numbers[restart] == 1 and numbers[restart - 1] > 50, "numbers from 1 again"
    before = np.diff(numbers[:restart])
    assert sorted(set(before.tolist())) == [1, 5], "the slow client's 4 frames skipped"
    truth = server.truth()
    assert len(truth["late"]) == 3 and len(truth["skipped"]) == 4
    first_late = numbers.index(int(truth["late"][0]))
    held = got[first_late][1] - got[first_late - 1][1]
    assert held >= 0.04, held  # held back 50 ms after the last late frame was due
    assert [e["kind"] for e in server.fault_log] == ["late", "slow", "restart", "disconnect"]
