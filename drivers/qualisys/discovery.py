"""Finding QTM real-time servers: a short, read-only dialogue at known addresses.

``spotlab devices --probe`` asks :func:`detect_servers`: 127.0.0.1 at QTM's default
little-endian port (22223), the addresses in ``$SPOTLAB_QTM`` (comma-separated
``HOST[:PORT]``) and any it is given (a lab file's qualisys devices). At each, the
probe connects (0.5 s), expects QTM's welcome, sets version 1.25 and asks
``QTMVersion`` and ``GetParameters All``; it takes no control and streams nothing.
QTM's UDP discovery broadcast (port 22226) is not implemented.
"""

from __future__ import annotations

import os
import socket
import time
from collections.abc import Iterable

from spotlab.core.errors import ProtocolError
from spotlab.drivers.base import DeviceInfo
from spotlab.drivers.qualisys.protocol import (
    COMMAND,
    DEFAULT_PORT,
    EVENT,
    PROTOCOL_VERSION,
    XML,
    Packet,
    PacketSplitter,
    command_packet,
    parse_parameters,
)

ENV = "SPOTLAB_QTM"
WELCOME = "QTM RT Interface connected"
PROBE_TIMEOUT_S = 0.5


def probe_addresses(extra: Iterable[str] = ()) -> list[str]:
    """Addresses to probe, ``HOST:PORT``, each once: 127.0.0.1:22223, ``$SPOTLAB_QTM``,
    then ``extra``."""
    given = [f"127.0.0.1:{DEFAULT_PORT}"]
    given += [a.strip() for a in os.environ.get(ENV, "").split(",") if a.strip()]
    given += list(extra)
    out: list[str] = []
    for a in given:
        _host, sep, num = a.rpartition(":")
        address = a if sep and num.isdigit() else f"{a}:{DEFAULT_PORT}"
        if address not in out:
            out.append(address)
    return out


class _Dialogue:
    def __init__(self, sock: socket.socket, timeout: float) -> None:
        self.sock = sock
        self.timeout = timeout
        self.split = PacketSplitter()
        self.queue: list[Packet] = []

    def reply(self) -> Packet:
        deadline = time.monotonic() + self.timeout
        while True:
            while self.queue:
                p = self.queue.pop(0)
                if p.kind != EVENT:
                    return p
            left = deadline - time.monotonic()
            if left <= 0:
                raise TimeoutError("no reply")
            self.sock.settimeout(left)
            data = self.sock.recv(1 << 16)
            if not data:
                raise ConnectionError("closed")
            self.queue += self.split.feed(data)

    def ask(self, text: str) -> Packet:
        self.sock.sendall(command_packet(text))
        return self.reply()


def probe_server(address: str, timeout: float = PROBE_TIMEOUT_S) -> DeviceInfo | None:
    """The QTM real-time server at ``HOST:PORT``, or None if none answers as QTM does."""
    host, _, num = address.rpartition(":")
    try:
        with socket.create_connection((host, int(num)), timeout) as sock:
            talk = _Dialogue(sock, timeout)
            welcome = talk.reply()
            if (welcome.kind, welcome.text) != (COMMAND, WELCOME):
                return None
            version = talk.ask(f"Version {PROTOCOL_VERSION}")
            if version.kind != COMMAND or not version.text.startswith("Version set to"):
                return None
            qtm = talk.ask("QTMVersion")
            params = talk.ask("GetParameters All")
            p = parse_parameters(params.text) if params.kind == XML else None
    except (OSError, ValueError, ProtocolError):
        return None
    name = qtm.text if qtm.kind == COMMAND else "QTM"
    extra = {"protocol_version": PROTOCOL_VERSION}
    if p is not None:
        extra.update(p.to_dict())
    return DeviceInfo(
        "qualisys", address, f"{name} (real-time protocol {PROTOCOL_VERSION})", "", extra
    )


def detect_servers(extra: Iterable[str] = ()) -> list[DeviceInfo]:
    """QTM servers answering at :func:`probe_addresses` (``extra``: more ``HOST[:PORT]``)."""
    found = (probe_server(a) for a in probe_addresses(extra))
    return [d for d in found if d is not None]
