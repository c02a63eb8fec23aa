"""A Qualisys QTM real-time server as a spotlab device (docs/protocols/qualisys.md).

Bring-up over TCP: the server's welcome, ``Version 1.25``, ``GetParameters
All`` (rate, labels, bodies, cameras), ``TakeControl`` when a password is
given, then ``StreamFrames AllFrames 3D 6D`` (with ``UDP:PORT`` when ``udp_port`` is
given: the Data packets then come as UDP datagrams, :mod:`.udp`, and the TCP
connection is read a whole packet at a time). Every byte read and written goes
to the taps, so a recording holds QTM's packets raw; the decoder
(:class:`QualisysDecoder`) turns them into frame blocks live and in replay.
``stop`` sends ``StreamFrames Stop`` then ``Version`` and decodes the stream up to
the reply to ``Version`` (:meth:`QualisysDriver.drain` hands those frames over), so
no frame QTM served before the stop is lost.

A lost connection (the server closes it, an error, or nothing at all for
max(2 s, 20 frame periods)) emits ``disconnected``; ``recv`` then tries every
50 ms to connect again, checks that QTM still has the same labels and streams
again (``reconnected``, one gap), as the MCS-1 drivers do. No thread is used.
"""

from __future__ import annotations

import os
import select
import socket
import time
from collections.abc import Sequence
from typing import Any

from spotlab.core.errors import (
    ConfigurationError,
    DeviceDisconnected,
    DeviceError,
    DeviceNotFound,
    DeviceTimeout,
    ProtocolError,
)
from spotlab.core.frames import FrameBlock
from spotlab.core.streams import StreamSpec
from spotlab.drivers.base import DeviceInfo, Driver
from spotlab.drivers.qualisys.decoder import QualisysDecoder
from spotlab.drivers.qualisys.discovery import detect_servers
from spotlab.drivers.qualisys.protocol import (
    COMMAND,
    DEFAULT_PORT,
    ERROR,
    EVENT,
    EVENTS,
    HEADER,
    MAX_PACKET,
    PACKET_NAMES,
    PROTOCOL_VERSION,
    XML,
    Packet,
    QtmParameters,
    command_packet,
    parse_parameters,
)
from spotlab.drivers.qualisys.udp import UdpReceiver

WELCOME = "QTM RT Interface connected"
RETRY_S = 0.05


def parse_address(port: str) -> tuple[str, int]:
    """``HOST[:PORT]`` -> (host, port); the port defaults to QTM's 22223.

    Raises
    ------
    ConfigurationError
        If the host is empty or the port is not 1-65535.
    """
    host, sep, num = port.rpartition(":")
    if not sep:
        host, num = port, str(DEFAULT_PORT)
    try:
        number = int(num)
    except ValueError:
        number = -1
    if not host or not 1 <= number <= 65535:
        raise ConfigurationError(f"a qualisys port is HOST[:PORT] (PORT 1-65535), got {port!r}")
    return host, number


class QualisysDriver(Driver):
    """Labelled 3-D markers (and 6D bodies) from a QTM real-time server.

    Parameters
    ----------
    port : str
        ``HOST[:PORT]`` of QTM's little-endian real-time port (default port 22223).
    name : str, optional
        Stream name (default ``"qualisys"``).
    password : str, optional
        QTM's real-time password: the driver takes control (``TakeControl``) with it.
    reply_timeout : float
        Seconds to wait for the connection and each reply (default 3).
    reconnect_timeout : float, optional
        Seconds to keep trying after the connection is lost (default: forever).
    udp_port : int, optional
        Have QTM send the frames as UDP datagrams to this local port (0: a free one);
        default: frames come on the TCP connection.

    Raises
    ------
    ConfigurationError
        If the port, the UDP port or a timeout is invalid.
    """

    family = "qualisys"

    def __init__(
        self,
        port: str | os.PathLike[str],
        *,
        name: str | None = None,
        password: str | None = None,
        reply_timeout: float = 3.0,
        reconnect_timeout: float | None = None,
        udp_port: int | None = None,
    ) -> None:
        super().__init__(port, name=name)
        self.host, self.tcp_port = parse_address(self.port)
        if not reply_timeout > 0:
            raise ConfigurationError(f"reply_timeout must be positive, got {reply_timeout}")
        self.password = password
        self.reply_timeout = reply_timeout
        self.reconnect_timeout = reconnect_timeout
        if udp_port is not None and not 0 <= udp_port <= 65535:
            raise ConfigurationError(f"udp_port must be 0-65535, got {udp_port}")
        self.udp_port = udp_port
        self._udp: UdpReceiver | None = None
        self.parameters: QtmParameters | None = None
        self.qtm_events: list[str] = []
        self._sock: socket.socket | None = None
        self._decoder: QualisysDecoder | None = None
        self._spec: StreamSpec | None = None
        self._lost_at: float | None = None
        self._next_try = 0.0
        self._last_rx = 0.0
        self._stash: list[FrameBlock] = []

    @classmethod
    def detect(cls, addresses: Sequence[str] = ()) -> list[DeviceInfo]:
        """QTM servers at 127.0.0.1:22223, at ``$SPOTLAB_QTM`` and at ``addresses``
        (:func:`~spotlab.drivers.qualisys.discovery.detect_servers`)."""
        return detect_servers(addresses)

    # -- description --------------------------------------------------------------
    @property
    def spec(self) -> StreamSpec:
        """The stream, from QTM's parameters (known after start)."""
        if self._spec is None:
            raise DeviceError(f"{self.name}: the QTM stream is known only after start()")
        return self._spec

    @property
    def decoder(self) -> QualisysDecoder:
        """The live decoder (after start)."""
        if self._decoder is None:
            raise DeviceError(f"{self.name}: not started")
        return self._decoder

    def metadata(self) -> dict[str, Any]:
        """Spec, QTM's parameters and the decoder's path."""
        params = self.parameters.to_dict() if self.parameters is not None else {}
        return {
            **super().metadata(),
            "qtm": {**params, "protocol_version": PROTOCOL_VERSION, "udp_port": self.udp_port},
            "decoder": "spotlab.drivers.qualisys:decoder_from_metadata",
        }

    # -- life cycle ---------------------------------------------------------------
    def _start(self) -> None:
        params = self._bring_up()
        self.parameters = params
        self._spec = StreamSpec(
            name=self.name,
            kind="point3d",
            n_sensors=1,
            n_markers=len(params.labels),
            rate_hz=params.rate_hz,
            tick_hz=1e6,
            values=("x", "y", "z"),
            units=("mm", "mm", "mm"),
            metadata={"marker_labels": list(params.labels), "bodies": list(params.bodies)},
        )
        self._decoder = QualisysDecoder(len(params.labels), self.stats)
        if self.udp_port is not None:
            self._open_udp()
        self._tap_event("started", components="3D 6D")
        self._send(self._stream_command())
        self._last_rx = time.monotonic()

    def _open_udp(self) -> None:
        assert self._sock is not None
        local = str(self._sock.getsockname()[0])
        try:
            self._udp = UdpReceiver(local, self.udp_port or 0, self.host)
        except OSError as exc:
            self._sock.close()
            self._sock = None
            raise ConfigurationError(
                f"cannot receive QTM's UDP stream on {local}:{self.udp_port}: {exc}"
            ) from None
        self._tap_event("udp", port=self._udp.port)

    def _stream_command(self) -> str:
        """``StreamFrames AllFrames [UDP:PORT] 3D 6D``."""
        udp = f" UDP:{self._udp.port}" if self._udp is not None else ""
        return f"StreamFrames AllFrames{udp} 3D 6D"

    def _stop(self) -> None:
        if self._sock is not None:
            try:
                self._send("StreamFrames Stop")
                self._receive_until_reply()
                if self.password is not None:
                    self._send("ReleaseControl")
            except OSError:
                pass
            self._tap_event("stopped")

    def _receive_until_reply(self) -> None:
        """Receive what QTM sent before it read ``StreamFrames Stop`` (which has no reply):
        ask ``Version`` and decode the stream up to its reply (replies come in order),
        keeping the frames for :meth:`drain`, so a recording ends with the last frame
        QTM served."""
        assert self._sock is not None and self._decoder is not None
        dec = self._decoder
        replies = dec.packets.get(COMMAND, 0) + dec.packets.get(ERROR, 0)
        self._send("Version")
        deadline = time.monotonic() + self.reply_timeout
        while dec.packets.get(COMMAND, 0) + dec.packets.get(ERROR, 0) == replies:
            left = deadline - time.monotonic()
            if left <= 0 or not select.select([self._sock], [], [], left)[0]:
                self._tap_event("stop_unconfirmed", reason="no reply to Version after Stop")
                return
            data = self._tcp_bytes()
            if not data:
                return
            self._take(data)
        if self._udp is not None:
            self._take(self._udp.drain())

    def _tcp_bytes(self) -> bytes:
        """What the TCP connection has: any bytes, or one whole packet when the frames
        come by UDP (so that datagrams never land inside a TCP packet in the journal)."""
        assert self._sock is not None
        if self._udp is None:
            return self._sock.recv(1 << 16)
        head = self._read_exact(HEADER.size, "the stream")
        size = max(HEADER.size, min(HEADER.unpack(head)[0], MAX_PACKET))
        return head + self._read_exact(size - HEADER.size, "the stream")

    def _take(self, data: bytes) -> FrameBlock | None:
        """Tap, count and decode received bytes; frames go to the stash."""
        if not data:
            return None
        assert self._decoder is not None
        arrival = time.monotonic_ns()
        self.stats.bytes += len(data)
        self._tap_rx(data, arrival)
        block = self._decoder.feed(data, arrival)
        if len(block):
            self._stash.append(block)
        return block

    def drain(self) -> list[FrameBlock]:
        """Frames received while stopping (before QTM's reply that ends the stream),
        handed over once."""
        blocks, self._stash = self._stash, []
        return blocks

    def _close(self) -> None:
        if self._udp is not None:
            self._udp.close()
            self._udp = None
        if self._sock is not None:
            self._sock.close()
            self._sock = None
            self._tap_event("close", port=self.port)

    # -- the dialogue ---------------------------------------------------------------
    def _bring_up(self) -> QtmParameters:
        """Connect, negotiate, read the parameters, take control if asked."""
        try:
            sock = socket.create_connection((self.host, self.tcp_port), self.reply_timeout)
        except OSError as exc:
            raise DeviceNotFound(
                f"no QTM real-time server at {self.host}:{self.tcp_port}: {exc}"
            ) from None
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._sock = sock
        self._tap_event("open", port=self.port)
        try:
            welcome = self._reply("the connection")
            if welcome.kind != COMMAND or welcome.text != WELCOME:
                raise ProtocolError(
                    f"{self.host}:{self.tcp_port} is not a QTM real-time server: it said "
                    f"{PACKET_NAMES[welcome.kind]} {welcome.text!r} when connected"
                )
            version = self._command(f"Version {PROTOCOL_VERSION}")
            if not version.text.startswith("Version set to"):
                raise ProtocolError(f"QTM answered {version.text!r} to Version")
            params = parse_parameters(self._command("GetParameters All", XML).text)
            if self.password is not None:
                self._command(f"TakeControl {self.password}", expect_prefix="You are now master")
        except BaseException:
            sock.close()
            self._sock = None
            raise
        if not params.labels:
            raise ConfigurationError(
                f"QTM at {self.port} has no labelled markers (The_3D has no Label): nothing to "
                "record as labelled 3-D"
            )
        self._tap_event("configured", rate_hz=params.rate_hz, labels=len(params.labels))
        return params

    def _send(self, text: str) -> None:
        assert self._sock is not None
        data = command_packet(text)
        self._sock.sendall(data)
        self._tap_tx(data, time.monotonic_ns())

    def _command(self, text: str, kind: int = COMMAND, expect_prefix: str = "") -> Packet:
        """Send a command, return its reply; an Error packet raises DeviceError."""
        self._send(text)
        reply = self._reply(text)
        if reply.kind == ERROR:
            if text.startswith("Version"):
                raise DeviceError(
                    f"QTM at {self.port} does not speak real-time protocol version "
                    f"{PROTOCOL_VERSION} (it answered {reply.text!r})"
                )
            raise DeviceError(f"QTM at {self.port} refused {text.split()[0]}: {reply.text}")
        if reply.kind != kind or not reply.text.startswith(expect_prefix):
            raise ProtocolError(
                f"QTM answered {text.split()[0]} with {PACKET_NAMES[reply.kind]} "
                f"{reply.text[:80]!r}"
            )
        return reply

    def _reply(self, what: str) -> Packet:
        """The next packet that is not an event (events are noted)."""
        while True:
            head = self._read_exact(HEADER.size, what)
            size, kind = HEADER.unpack(head)
            if not HEADER.size <= size <= MAX_PACKET or kind >= len(PACKET_NAMES):
                raise ProtocolError(
                    f"{self.host}:{self.tcp_port} sent a header no QTM sends "
                    f"({head.hex(' ')}) in reply to {what}"
                )
            body = self._read_exact(size - HEADER.size, what)
            self._tap_rx(head + body, time.monotonic_ns())
            if kind == EVENT and body:
                self.qtm_events.append(EVENTS.get(body[0], f"event {body[0]}"))
                continue
            return Packet(kind, body)

    def _read_exact(self, n: int, what: str) -> bytes:
        assert self._sock is not None
        out = bytearray()
        deadline = time.monotonic() + self.reply_timeout
        while len(out) < n:
            self._sock.settimeout(max(0.001, deadline - time.monotonic()))
            try:
                chunk = self._sock.recv(n - len(out))
            except TimeoutError:
                raise DeviceTimeout(
                    f"QTM at {self.port} did not answer {what} within {self.reply_timeout:g} s"
                ) from None
            except OSError as exc:
                raise DeviceDisconnected(f"QTM at {self.port}: {exc}") from None
            if not chunk:
                raise DeviceDisconnected(f"QTM at {self.port} closed the connection ({what})")
            out += chunk
        return bytes(out)

    # -- streaming ------------------------------------------------------------------
    def _silence_s(self) -> float:
        rate = self._spec.rate_hz if self._spec is not None else 100.0
        return max(2.0, 20.0 / rate)

    def _recv_internal(self, timeout: float | None) -> FrameBlock | None:
        if self._decoder is None:
            raise DeviceError(f"{self.name} ({self.port}) is not streaming: call start() first")
        if self._sock is None:
            self._recover()
            if self._sock is None:
                time.sleep(min(RETRY_S, timeout if timeout is not None else RETRY_S))
                return None
        wait = self._silence_s() if timeout is None else min(timeout, self._silence_s())
        sources: list[Any] = [self._sock] if self._udp is None else [self._sock, self._udp]
        ready, _, _ = select.select(sources, [], [], wait)
        now = time.monotonic()
        if not ready:
            if now - self._last_rx > self._silence_s():
                self._lose(f"no data for {now - self._last_rx:.1f} s")
            return None
        data = b""
        if self._sock in ready:
            try:
                data = self._tcp_bytes()
            except (OSError, DeviceError) as exc:
                self._lose(str(exc))
                return None
            if not data:
                self._lose("QTM closed the connection")
                return None
        if self._udp is not None and self._udp in ready:
            data += self._udp.read_available()
        if not data:
            return None
        self._last_rx = now
        arrival = time.monotonic_ns()
        self.stats.bytes += len(data)
        self._tap_rx(data, arrival)
        return self._decoder.feed(data, arrival)

    def _lose(self, reason: str) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None
        self._lost_at = time.monotonic()
        self._next_try = self._lost_at
        assert self._decoder is not None
        self._decoder.mark_discontinuity()
        self._tap_event("disconnected", reason=reason)

    def _recover(self) -> None:
        now = time.monotonic()
        lost = self._lost_at if self._lost_at is not None else now
        if self.reconnect_timeout is not None and now - lost > self.reconnect_timeout:
            raise DeviceDisconnected(
                f"QTM at {self.port} did not come back within {self.reconnect_timeout:g} s"
            )
        if now < self._next_try:
            return
        self._next_try = now + RETRY_S
        try:
            params = self._bring_up()
        except (DeviceError, ProtocolError, OSError):
            return
        if self.parameters is not None and params.labels != self.parameters.labels:
            assert self._sock is not None
            self._sock.close()
            self._sock = None
            raise ConfigurationError(
                f"QTM at {self.port} came back with other labels "
                f"({len(params.labels)} instead of {len(self.parameters.labels)}): "
                "record again to follow the new set-up"
            )
        assert self._decoder is not None
        self._decoder.mark_discontinuity()
        self.stats.reconnects += 1
        self.stats.gaps += 1
        self._tap_event("reconnected", outage_s=round(time.monotonic() - lost, 3))
        self._send(self._stream_command())
        self._last_rx = time.monotonic()
        self._lost_at = None
