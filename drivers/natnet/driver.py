"""An OptiTrack Motive NatNet server as a spotlab device (docs/protocols/natnet.md).

The driver is a NatNet client: from one UDP socket it sends ``NAT_CONNECT`` to
the server's command port, reads the server info (NatNet version, clock, data
port, multicast group), asks for the model descriptions (the marker set's
labels), then receives the frames: unicast, those the server sends to that
socket; multicast (the server info announces it, or ``multicast=GROUP`` asks
for it), those sent to the group on the data port, received on a second socket
that joins the group on the interface that routes to the server. It sends
``NAT_KEEPALIVE`` once a second, and ``NAT_DISCONNECT`` when closed. The first
frames give the frame rate (NatNet does not describe it). Every datagram
received is journalled raw; the stream is ``point3d``: the marker set's labelled
markers, x, y, z in mm. The rigid bodies ride in the same frames: see
:func:`spotlab.drivers.natnet.bodies.bodies_from_recording`.
"""

from __future__ import annotations

import os
import select
import socket
import time
from typing import Any

import numpy as np

from spotlab.core.errors import (
    ConfigurationError,
    DeviceDisconnected,
    DeviceError,
    DeviceNotFound,
    ProtocolError,
)
from spotlab.core.frames import FrameBlock
from spotlab.core.streams import StreamSpec
from spotlab.drivers.base import DeviceInfo, Driver
from spotlab.drivers.natnet.decoding import LAYOUT, NatNetDecoder
from spotlab.drivers.natnet.multicast import check_group, join_group, local_address
from spotlab.drivers.natnet.probe import detect_servers, probe_addresses
from spotlab.drivers.natnet.wire import (
    MAJORS,
    NAT_DISCONNECT,
    NAT_FRAMEOFDATA,
    NAT_KEEPALIVE,
    NAT_MODELDEF,
    NAT_REQUEST_MODELDEF,
    NAT_SERVERINFO,
    FrameOfData,
    ModelDefinitions,
    NatNetFormatError,
    ServerInfo,
    connect_request,
    parse_frame,
    parse_model_definitions,
    parse_server_info,
    request,
    split_packet,
)

DEFAULT_PORT = 1510
#: Frames read at start to measure the frame rate.
RATE_FRAMES = 5
KEEPALIVE_S = 1.0
_FRAME_ID = NAT_FRAMEOFDATA.to_bytes(2, "little")


def parse_address(port: str) -> tuple[str, int]:
    """``HOST`` or ``HOST:PORT`` (command port, default 1510) of a NatNet server.

    Raises
    ------
    ConfigurationError
        If the port number is not 1-65535 or the host is empty.
    """
    host, sep, number = port.rpartition(":")
    if not sep:
        host, number = port, str(DEFAULT_PORT)
    try:
        value = int(number)
    except ValueError:
        value = -1
    if not host or not 1 <= value <= 65535:
        raise ConfigurationError(f"a NatNet server is HOST or HOST:PORT, got {port!r}")
    return host, value


class NatNetDriver(Driver):
    """A NatNet server's labelled markers as a ``point3d`` stream.

    Parameters
    ----------
    port : str
        ``HOST`` or ``HOST:PORT`` of the server's command port (default port 1510).
    name : str, optional
        Stream name (default ``"natnet"``).
    marker_set : str, optional
        The marker set to stream (default: the first described one that is not
        Motive's ``all``).
    reply_timeout : float
        Seconds to wait for each reply (server info, model descriptions); 3 tries.
    silence_timeout : float
        Seconds without a datagram after which the server counts as gone (a
        ``disconnected`` event); the driver then sends ``NAT_CONNECT`` every second
        and goes on (``reconnected``) when the server answers or streams again.
    reconnect_timeout : float, optional
        Seconds of absence after which ``recv`` raises ``DeviceDisconnected``
        (default: never; the session's end or a stop ends the wait).
    multicast : str, optional
        ``None`` (default): receive as the server info announces (unicast, or its
        multicast group on its data port); a group address (``239.255.42.99``):
        join that group whatever the server announces; ``"off"``: unicast.
    """

    family = "natnet"

    def __init__(
        self,
        port: str | os.PathLike[str],
        *,
        name: str | None = None,
        marker_set: str | None = None,
        reply_timeout: float = 1.0,
        silence_timeout: float = 2.0,
        reconnect_timeout: float | None = None,
        multicast: str | None = None,
    ) -> None:
        super().__init__(port, name=name)
        self.address = parse_address(self.port)
        self.want_multicast = check_group(multicast)
        if not reply_timeout > 0 or not silence_timeout > 0:
            raise ConfigurationError("NatNet timeouts must be positive")
        self.want_set = marker_set
        self.reply_timeout = reply_timeout
        self.silence_timeout = silence_timeout
        self.reconnect_timeout = reconnect_timeout
        self._away_since: float | None = None
        self.server: ServerInfo | None = None
        self.models: ModelDefinitions | None = None
        self.marker_set = ""
        self.labels: tuple[str, ...] = ()
        self.rate_hz = 0.0
        self._sock: socket.socket | None = None
        #: The multicast data socket, when frames come to a group.
        self._data: socket.socket | None = None
        #: ``(group, data port)`` joined, or None (unicast).
        self.group: tuple[str, int] | None = None
        self._decoder: NatNetDecoder | None = None
        self._spec: StreamSpec | None = None
        self._pending: list[tuple[bytes, int]] = []
        self._last_rx = 0.0
        self._last_keepalive = 0.0

    # -- description ---------------------------------------------------------------
    @property
    def spec(self) -> StreamSpec:
        """Labelled markers of the marker set, known after start."""
        if self._spec is None:
            raise DeviceError(f"{self.name}: the NatNet stream is known only after start()")
        return self._spec

    @property
    def version(self) -> tuple[int, int]:
        """The server's NatNet version (major, minor)."""
        if self.server is None:
            raise DeviceError(f"{self.name}: the NatNet version is known only after start()")
        return self.server.version

    @property
    def last_frame(self) -> FrameOfData | None:
        """The last frame decoded (its rigid bodies, labelled markers, timecode)."""
        return None if self._decoder is None else self._decoder.last_frame

    def metadata(self) -> dict[str, Any]:
        """Spec, the server, its NatNet version, marker set and labels, journal layout."""
        server = self.server
        return {
            **super().metadata(),
            "natnet_version": list(self.version),
            "server": None
            if server is None
            else {
                "name": server.name,
                "app_version": list(server.app_version),
                "natnet_version": list(server.natnet_version),
                "clock_hz": server.clock_hz,
            },
            "marker_set": self.marker_set,
            "labels": list(self.labels),
            "multicast": None if self.group is None else f"{self.group[0]}:{self.group[1]}",
            "rigid_bodies": dict(self.models.rigid_bodies) if self.models else {},
            "layout": LAYOUT,
            "decoder": "spotlab.drivers.natnet:decoder_from_metadata",
        }

    # -- socket --------------------------------------------------------------------
    def _send(self, data: bytes) -> None:
        assert self._sock is not None
        try:
            self._sock.sendto(data, self.address)
        except OSError as exc:
            raise DeviceNotFound(f"{self.name}: cannot send to {self.port}: {exc}") from exc
        self._tap_tx(data, time.monotonic_ns())

    def _receive(self, timeout: float) -> list[tuple[bytes, int]]:
        """Datagrams that arrive within ``timeout`` s (all that wait, once one has come),
        with their arrival stamps; the caller taps them (frames at start-up only once
        the stream is described, so that the journal decodes them)."""
        assert self._sock is not None
        socks = [self._sock] if self._data is None else [self._sock, self._data]
        ready, _, _ = select.select(socks, [], [], max(0.0, timeout))
        out: list[tuple[bytes, int]] = []
        for sock in ready:
            while True:
                try:
                    data = sock.recv(65536)
                except BlockingIOError:
                    break
                except OSError as exc:  # ICMP port unreachable: nobody listens there
                    if out:
                        break
                    raise DeviceNotFound(
                        f"{self.name}: no NatNet server at {self.port}: {exc}"
                    ) from exc
                t_ns = time.monotonic_ns()
                self.stats.bytes += len(data)
                out.append((data, t_ns))
        if out:
            self._last_rx = time.monotonic()
        return out

    def _ask(self, packet: bytes, answer: int, what: str) -> bytes:
        """Send ``packet`` until the message ``answer`` comes (3 tries); frames that come
        meanwhile are kept for the stream."""
        for _ in range(3):
            self._send(packet)
            deadline = time.monotonic() + self.reply_timeout
            while time.monotonic() < deadline:
                for data, t_ns in self._receive(deadline - time.monotonic()):
                    if data[:2] == _FRAME_ID:
                        self._pending.append((data, t_ns))
                        continue
                    self._tap_rx(data, t_ns)
                    try:
                        message_id, payload = split_packet(data)
                    except NatNetFormatError as exc:
                        raise ProtocolError(f"{self.name}: not a NatNet server: {exc}") from exc
                    if message_id == answer:
                        return payload
        raise DeviceNotFound(
            f"{self.name}: no {what} from a NatNet server at {self.port} "
            f"within 3 x {self.reply_timeout:g} s"
        )

    # -- life cycle ----------------------------------------------------------------
    def _start(self) -> None:
        self._away_since = None
        if self._sock is None:
            family = socket.AF_INET6 if ":" in self.address[0] else socket.AF_INET
            self._sock = socket.socket(family, socket.SOCK_DGRAM)
            self._sock.setblocking(False)
            self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
            self._tap_event("open", port=self.port)
        self._pending.clear()
        try:
            info = parse_server_info(self._ask(connect_request(), NAT_SERVERINFO, "server info"))
        except NatNetFormatError as exc:
            raise ProtocolError(f"{self.name}: bad NatNet server info: {exc}") from exc
        major, minor = info.version
        if major not in MAJORS:
            raise ProtocolError(
                f"{self.name}: the server at {self.port} speaks NatNet {major}.{minor}; "
                "this driver reads NatNet 3.x and 4.x"
            )
        self.server = info
        self._join(info)
        try:
            models = parse_model_definitions(
                self._ask(request(NAT_REQUEST_MODELDEF), NAT_MODELDEF, "model descriptions"),
                info.version,
            )
        except NatNetFormatError as exc:
            raise ProtocolError(f"{self.name}: bad NatNet model descriptions: {exc}") from exc
        self.models = models
        self.marker_set, self.labels = self._choose_set(models)
        self.rate_hz = self._measure_rate()
        self._decoder = NatNetDecoder(info.version, self.marker_set, self.labels, self.stats)
        tick_hz = float(info.clock_hz) if major >= 3 and info.clock_hz > 0 else 1e6
        self._spec = StreamSpec(
            name=self.name,
            kind="point3d",
            n_sensors=1,
            n_markers=len(self.labels),
            rate_hz=self.rate_hz,
            tick_hz=tick_hz,
            values=("x", "y", "z"),
            units=("mm", "mm", "mm"),
            metadata={"marker_labels": list(self.labels), "marker_set": self.marker_set},
        )
        self._last_keepalive = time.monotonic()
        self._tap_event("started", natnet_version=f"{major}.{minor}", rate_hz=self.rate_hz)

    def _join(self, info: ServerInfo) -> None:
        """Open the multicast data socket when frames come to a group (once per open)."""
        want = self.want_multicast
        if want == "off" or (want is None and not info.multicast):
            return
        group = want if want is not None else info.group
        data_port = info.data_port or DEFAULT_PORT + 1
        if self._data is not None:
            if self.group == (group, data_port):
                return
            self._leave()
        try:
            self._data = join_group(group, data_port, local_address(self.address))
        except OSError as exc:
            raise DeviceNotFound(
                f"{self.name}: cannot join the NatNet multicast group {group}:{data_port}: {exc}"
            ) from exc
        self.group = (group, data_port)
        self._tap_event("joined", group=f"{group}:{data_port}")

    def _leave(self) -> None:
        if self._data is not None:
            self._data.close()
            self._data = None
            self.group = None

    @classmethod
    def detect(cls) -> list[DeviceInfo]:
        """NatNet servers that answer at ``127.0.0.1:1510``, or at the addresses of the
        environment variable ``SPOTLAB_NATNET_PROBE`` (``HOST[:PORT]``, comma-separated)."""
        addresses = []
        for text in probe_addresses():
            try:
                addresses.append(parse_address(text))
            except ConfigurationError:
                continue
        return detect_servers(addresses)

    def _choose_set(self, models: ModelDefinitions) -> tuple[str, tuple[str, ...]]:
        sets = models.marker_sets
        if self.want_set is not None:
            if self.want_set not in sets:
                raise ConfigurationError(
                    f"{self.name}: no marker set {self.want_set!r}; the server has {sorted(sets)}"
                )
            return self.want_set, sets[self.want_set]
        for name, labels in sets.items():
            if name.lower() != "all" and labels:
                return name, labels
        raise DeviceError(f"{self.name}: the NatNet server at {self.port} describes no marker set")

    def _measure_rate(self) -> float:
        """Frames per second from the first frames' timestamps (kept for the stream)."""
        assert self.server is not None
        deadline = time.monotonic() + max(2.0, self.reply_timeout)
        while len(self._pending) < RATE_FRAMES and time.monotonic() < deadline:
            for data, t_ns in self._receive(deadline - time.monotonic()):
                if data[:2] == _FRAME_ID:
                    self._pending.append((data, t_ns))
                else:
                    self._tap_rx(data, t_ns)
        stamps = []
        for data, _ in self._pending:
            try:
                f = parse_frame(split_packet(data)[1], self.server.version)
            except NatNetFormatError:
                continue  # the decoder counts it
            stamps.append((f.frame_number, f.timestamp_s))
        if len(stamps) < 2:
            raise DeviceNotFound(f"{self.name}: the NatNet server at {self.port} sends no frames")
        k, t = np.asarray(stamps, dtype=np.float64).T
        steps = np.diff(t) / np.diff(k)
        steps = steps[np.isfinite(steps) & (steps > 0)]
        if not steps.size:
            raise ProtocolError(f"{self.name}: NatNet frame timestamps do not advance")
        return float(round(1.0 / float(np.median(steps)), 3))

    def _stop(self) -> None:
        self._tap_event("stopped")

    def _close(self) -> None:
        if self._sock is not None:
            if self.server is not None:
                try:  # the server may stop sending to us at once
                    self._sock.sendto(request(NAT_DISCONNECT), self.address)
                except OSError:
                    pass
            self._sock.close()
            self._sock = None
            self._leave()
            self._tap_event("close", port=self.port)

    # -- streaming -----------------------------------------------------------------
    def _recv_internal(self, timeout: float | None) -> FrameBlock | None:
        if self._sock is None or self._decoder is None:
            raise DeviceError(f"{self.name} ({self.port}) is not streaming: call start() first")
        now = time.monotonic()
        if now - self._last_keepalive >= KEEPALIVE_S:
            # While the server is away, ask it in again; else keep the subscription.
            away = self._away_since is not None
            self._send(connect_request() if away else request(NAT_KEEPALIVE))
            self._last_keepalive = now
        got, self._pending = self._pending, []
        if not got:
            wait = KEEPALIVE_S if timeout is None else min(timeout, KEEPALIVE_S)
            got = self._receive(wait)
        if not got:
            self._check_silence()
            return None
        if self._away_since is not None:
            self._away_since = None
            self.stats.reconnects += 1
            self._tap_event("reconnected", port=self.port)
        for data, t_ns in got:
            self._tap_rx(data, t_ns)
        blocks = [self._decoder.feed(data, t_ns) for data, t_ns in got]
        blocks = [b for b in blocks if len(b)]
        if not blocks:
            return None
        return blocks[0] if len(blocks) == 1 else FrameBlock.concat(blocks)

    def _check_silence(self) -> None:
        """After ``silence_timeout`` s without a datagram the server is away: say so once,
        then ask it in again every second; give up after ``reconnect_timeout`` s."""
        assert self._decoder is not None
        now = time.monotonic()
        if self._away_since is None:
            if now - self._last_rx <= self.silence_timeout:
                return
            self._away_since = now
            self.stats.gaps += 1
            self._decoder.mark_discontinuity()
            reason = f"no NatNet datagram from {self.port} for {self.silence_timeout:g} s"
            self._tap_event("disconnected", reason=reason)
        elif self.reconnect_timeout is not None and now - self._away_since > self.reconnect_timeout:
            raise DeviceDisconnected(
                f"{self.name}: the NatNet server at {self.port} has sent nothing for "
                f"{now - self._last_rx:.1f} s"
            )
