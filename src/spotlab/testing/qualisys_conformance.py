"""Conformance suite of a QTM real-time server: the simulator in CI, a real QTM on a lab PC.

``pytest tests/conformance/test_qualisys.py --hw qualisys=HOST[:PORT]`` runs it
against a real Qualisys Track Manager (port 22223 by default, the little-endian
real-time port). QTM must be running a measurement or its real-time preview
with at least one labelled marker in the project's label list (AIM or a
label list), and "Allow client control" on. Give QTM's real-time password in
``SPOTLAB_QTM_PASSWORD`` to run the take-control tests (skipped without it on
hardware); ``SPOTLAB_QTM_SECONDS`` sets how long the streaming tests stream
(default 2 s).

Every assertion holds of any QTM speaking protocol 1.25 as documented
(docs/protocols/qualisys.md): replies, packet types, contiguous frame numbers,
timestamps one frame period apart, the 3D and 6D components as large as the
parameters say. Nothing here knows what the simulator measures. The
reconnection test puts a :class:`~spotlab.testing.tcp_cut.CuttableRelay` in
front of the server and drops the connection there, so it needs no help from
QTM either.

Subclass :class:`QualisysConformance`; it provides the ``qtm_address`` and
``qtm_password`` fixtures (override them to test another server).
"""

from __future__ import annotations

import os
import socket
import time
import xml.etree.ElementTree as ET
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import pytest

from spotlab.core.frames import FrameBlock
from spotlab.drivers.qualisys import (
    QtmParameters,
    QualisysDriver,
    bodies_6d_from,
    command_packet,
    markers_3d_from,
    parse_address,
    parse_data,
    parse_parameters,
)
from spotlab.drivers.qualisys.protocol import (
    COMMAND,
    COMP_3D,
    COMP_6D,
    DATA,
    ERROR,
    EVENT,
    NO_MORE_DATA,
    XML,
    Packet,
    PacketSplitter,
)
from spotlab.testing.pytest_plugin import hardware_ports
from spotlab.testing.tcp_cut import CuttableRelay

WELCOME = "QTM RT Interface connected"
VERSION = "1.25"
#: The password the CI simulator asks for.
SIM_PASSWORD = "spotlab-conformance"  # noqa: S105 (the simulator's, not a secret)
PASSWORD_ENV = "SPOTLAB_QTM_PASSWORD"  # noqa: S105 (a variable name)
SECONDS_ENV = "SPOTLAB_QTM_SECONDS"


def stream_seconds() -> float:
    """How long the streaming tests stream (``SPOTLAB_QTM_SECONDS``, default 2)."""
    return float(os.environ.get(SECONDS_ENV, "2"))


class QtmLink:
    """One raw connection to a QTM real-time server: commands out, packets in.

    Parameters
    ----------
    address : str
        ``HOST[:PORT]``.
    timeout : float
        Seconds to wait for the connection and for each reply.
    """

    def __init__(self, address: str, timeout: float = 3.0) -> None:
        host, port = parse_address(address)
        self.timeout = timeout
        self.sock = socket.create_connection((host, port), timeout)
        self.split = PacketSplitter()
        self.queue: list[Packet] = []
        self.events: list[int] = []

    def close(self) -> None:
        """Close the connection."""
        self.sock.close()

    def __enter__(self) -> QtmLink:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def send(self, text: str) -> None:
        """Send a Command packet."""
        self.sock.sendall(command_packet(text))

    def packet(self, timeout: float | None = None) -> Packet | None:
        """The next packet (events included), or None after ``timeout`` s of silence.

        Raises
        ------
        ConnectionError
            If the server closed the connection.
        """
        deadline = time.monotonic() + (self.timeout if timeout is None else timeout)
        while not self.queue:
            left = deadline - time.monotonic()
            if left <= 0:
                return None
            self.sock.settimeout(left)
            try:
                data = self.sock.recv(1 << 16)
            except TimeoutError:
                return None
            if not data:
                raise ConnectionError("the QTM server closed the connection")
            self.queue += self.split.feed(data)
        return self.queue.pop(0)

    def reply(self, timeout: float | None = None) -> Packet:
        """The next packet that is not an Event (events are kept in ``events``)."""
        while True:
            p = self.packet(timeout)
            assert p is not None, "no reply within the timeout"
            if p.kind == EVENT:
                self.events.append(p.body[0] if p.body else -1)
                continue
            return p

    def ask(self, text: str) -> Packet:
        """Send a command and return its reply."""
        self.send(text)
        return self.reply()

    def welcomed(self) -> QtmLink:
        """Read the welcome and set the protocol version (asserting both)."""
        welcome = self.reply()
        assert (welcome.kind, welcome.text) == (COMMAND, WELCOME), welcome
        reply = self.ask(f"Version {VERSION}")
        assert (reply.kind, reply.text) == (COMMAND, f"Version set to {VERSION}"), reply
        return self

    def parameters(self) -> QtmParameters:
        """``GetParameters All``, parsed."""
        reply = self.ask("GetParameters All")
        assert reply.kind == XML, reply
        return parse_parameters(reply.text)


@dataclass
class Streamed:
    """Data packets of a stream: frame numbers, timestamps (µs), 3D and 6D per frame."""

    frames: list[int]
    stamps: list[int]
    markers: list[np.ndarray]
    bodies: list[tuple[np.ndarray, np.ndarray]]
    others: list[Packet]


def stream(link: QtmLink, seconds: float, components: str = "3D 6D") -> Streamed:
    """``StreamFrames AllFrames COMPONENTS`` for ``seconds``, then ``StreamFrames Stop``."""
    out = Streamed([], [], [], [], [])
    link.send(f"StreamFrames AllFrames {components}")
    t_end = time.monotonic() + seconds
    while time.monotonic() < t_end:
        p = link.packet(max(0.01, t_end - time.monotonic()))
        if p is None:
            continue
        if p.kind != DATA:
            out.others.append(p)
            continue
        frame = parse_data(p.body)
        out.frames.append(frame.frame)
        out.stamps.append(frame.timestamp_us)
        if COMP_3D in frame.components:
            out.markers.append(markers_3d_from(frame.components[COMP_3D]))
        if COMP_6D in frame.components:
            out.bodies.append(bodies_6d_from(frame.components[COMP_6D]))
    link.send("StreamFrames Stop")
    return out


def receive(driver: QualisysDriver, seconds: float) -> list[FrameBlock]:
    """Blocks the driver gives in ``seconds`` (empty ones dropped)."""
    blocks = []
    t_end = time.monotonic() + seconds
    while time.monotonic() < t_end:
        b = driver.recv(0.1)
        if b is not None and len(b):
            blocks.append(b)
    return blocks


class QualisysConformance:
    """Tests every QTM real-time server must pass (protocol 1.25, little-endian)."""

    @pytest.fixture
    def qtm_password(self, request: pytest.FixtureRequest) -> str | None:
        """QTM's real-time password: the simulator's, or ``SPOTLAB_QTM_PASSWORD``."""
        if hardware_ports(request.config).get("qualisys") is not None:
            return os.environ.get(PASSWORD_ENV)
        return SIM_PASSWORD

    @pytest.fixture
    def qtm_address(self, request: pytest.FixtureRequest) -> Iterator[str]:
        """``HOST:PORT`` of the server under test: ``--hw qualisys=...`` or a simulator."""
        hw = hardware_ports(request.config).get("qualisys")
        if hw is not None:
            host, port = parse_address(hw)
            yield f"{host}:{port}"
            return
        from spotlab.simulators.qualisys import QualisysServer, QualisysSimOptions

        options = QualisysSimOptions(markers=16, cameras=4, rate_hz=200.0, password=SIM_PASSWORD)
        with QualisysServer(options) as server:
            yield server.address

    # -- the dialogue -----------------------------------------------------------------
    def test_welcome_and_version_negotiation(self, qtm_address: str) -> None:
        with QtmLink(qtm_address) as link:
            link.welcomed()
            asked = link.ask("Version")
            assert (asked.kind, asked.text) == (COMMAND, f"Version is {VERSION}")
            order = link.ask("ByteOrder")
            assert order.kind == COMMAND and "little endian" in order.text.lower(), order

    def test_a_version_from_the_future_is_an_error(self, qtm_address: str) -> None:
        with QtmLink(qtm_address) as link:
            link.reply()  # the welcome
            refused = link.ask("Version 99.0")
            assert refused.kind == ERROR, refused

    def test_parameters_name_rate_labels_and_bodies(self, qtm_address: str) -> None:
        with QtmLink(qtm_address) as link:
            params = link.welcomed().parameters()
            only_3d = link.ask("GetParameters 3D")
            only_6d = link.ask("GetParameters 6D")
        assert params.rate_hz > 0
        assert params.labels, "QTM's project has no labelled markers (The_3D/Label)"
        assert all(params.labels) and len(set(params.labels)) == len(params.labels)
        assert all(params.bodies) and len(set(params.bodies)) == len(params.bodies)
        assert only_3d.kind == only_6d.kind == XML
        root3 = ET.fromstring(only_3d.text)  # noqa: S314 (a trusted server's reply)
        root6 = ET.fromstring(only_6d.text)  # noqa: S314
        assert tuple(e.text for e in root3.findall("The_3D/Label/Name")) == params.labels
        assert tuple(e.text for e in root6.findall("The_6D/Body/Name")) == params.bodies

    # -- streaming ----------------------------------------------------------------------
    def test_stream_3d_6d_contiguous_frames_one_period_apart(self, qtm_address: str) -> None:
        seconds = stream_seconds()
        with QtmLink(qtm_address) as link:
            params = link.welcomed().parameters()
            got = stream(link, seconds)
        no_data = [p for p in got.others if p.kind == NO_MORE_DATA]
        assert not no_data, "NoMoreData: QTM is not measuring (start its real-time preview)"
        assert not [p for p in got.others if p.kind == ERROR], got.others
        n = len(got.frames)
        expected = params.rate_hz * seconds
        assert 0.8 * expected - 2 <= n <= 1.05 * expected + 2, (n, expected)
        frames = np.array(got.frames, dtype=np.int64)
        assert np.all(np.diff(frames) == 1), "frame numbers skip or repeat"
        step = np.diff(np.array(got.stamps, dtype=np.int64)) / 1e6
        assert np.all(step > 0), "timestamps do not increase"
        np.testing.assert_allclose(np.median(step), 1.0 / params.rate_hz, rtol=0.01)
        assert len(got.markers) == len(got.bodies) == n
        assert all(m.shape == (len(params.labels), 3) for m in got.markers)
        markers = np.stack(got.markers)
        assert np.isfinite(markers).any(), "no labelled marker seen in any frame"
        for pos, rot in got.bodies:
            assert pos.shape == (len(params.bodies), 3)
            found = np.isfinite(rot).all(axis=(1, 2))
            gram = np.einsum("bji,bjk->bik", rot[found], rot[found])
            assert np.allclose(gram, np.eye(3), atol=1e-3), "a 6D rotation is not orthonormal"

    def test_stream_frames_stop_stops_the_data(self, qtm_address: str) -> None:
        with QtmLink(qtm_address) as link:
            link.welcomed()
            got = stream(link, 0.3, "3D")
            assert got.frames, "no frame streamed"
            late = []
            t_end = time.monotonic() + 0.5  # frames already on their way may still come
            while time.monotonic() < t_end:
                p = link.packet(0.05)
                if p is not None:
                    late.append(p)
            assert not [p for p in late if p.kind == ERROR], late
            after = link.packet(0.5)
            assert after is None or after.kind != DATA, "Data after StreamFrames Stop"
            alive = link.ask("Version")
            assert alive.kind == COMMAND and alive.text.startswith("Version is"), alive

    # -- control ---------------------------------------------------------------------------
    def test_take_control_refuses_a_wrong_password(
        self, qtm_address: str, qtm_password: str | None
    ) -> None:
        if qtm_password is None:
            pytest.skip(f"QTM's password unknown: set {PASSWORD_ENV} to test control")
        with QtmLink(qtm_address) as link:
            link.welcomed()
            wrong = link.ask(f"TakeControl {qtm_password}-not")
            assert wrong.kind == ERROR, wrong
            right = link.ask(f"TakeControl {qtm_password}")
            assert (right.kind, right.text.startswith("You are now master")) == (COMMAND, True)
            released = link.ask("ReleaseControl")
            assert released.kind == COMMAND and released.text.startswith(
                "You are now a regular client"
            ), released

    def test_only_one_client_is_master(self, qtm_address: str, qtm_password: str | None) -> None:
        if qtm_password is None:
            pytest.skip(f"QTM's password unknown: set {PASSWORD_ENV} to test control")
        with QtmLink(qtm_address) as first, QtmLink(qtm_address) as second:
            first.welcomed()
            second.welcomed()
            assert first.ask(f"TakeControl {qtm_password}").kind == COMMAND
            assert second.ask(f"TakeControl {qtm_password}").kind == ERROR
            assert first.ask("ReleaseControl").kind == COMMAND
            assert second.ask(f"TakeControl {qtm_password}").kind == COMMAND
            assert second.ask("ReleaseControl").kind == COMMAND

    # -- the driver ------------------------------------------------------------------------
    def test_driver_keeps_every_frame(self, qtm_address: str, qtm_password: str | None) -> None:
        driver = QualisysDriver(qtm_address, password=qtm_password)
        driver.start()
        try:
            block = FrameBlock.concat(receive(driver, stream_seconds()))
        finally:
            driver.close()
        assert driver.parameters is not None
        assert len(block) >= 0.8 * driver.parameters.rate_hz * stream_seconds() - 2
        assert np.all(np.diff(block.seq) == 1)
        assert driver.stats.lost_frames == 0 and driver.stats.gaps == 0
        assert block.data.shape[1:] == (len(driver.parameters.labels), 1, 3)
        assert driver.spec.metadata["marker_labels"] == list(driver.parameters.labels)

    def test_driver_reconnects_after_the_server_drops_it(self, qtm_address: str) -> None:
        host, port = parse_address(qtm_address)
        with CuttableRelay(host, port) as relay:
            driver = QualisysDriver(relay.address, reply_timeout=3.0, reconnect_timeout=10.0)
            driver.start()
            try:
                before = FrameBlock.concat(receive(driver, 0.5))
                relay.cut(refuse_s=0.2)
                t_end = time.monotonic() + 10.0
                while driver.stats.reconnects == 0 and time.monotonic() < t_end:
                    driver.recv(0.1)
                after = FrameBlock.concat(receive(driver, 0.5))
            finally:
                driver.close()
        assert len(before) and len(after), (len(before), len(after))
        assert driver.stats.reconnects == 1 and relay.accepted >= 2
        assert after.seq[0] > before.seq[-1]
        assert np.all(np.diff(after.seq) == 1) and np.all(np.diff(before.seq) == 1)
        assert after.ticks[0] > before.ticks[-1]
