"""Finding NatNet servers for ``spotlab devices --probe`` (docs/protocols/natnet.md §2).

A probe sends ``NAT_CONNECT`` to each address and waits briefly for the server
info; a server that answers is told ``NAT_DISCONNECT`` at once, so that it does
not stream to the probe. The addresses are ``127.0.0.1:1510`` (Motive on this
machine, its default command port), or those of the environment variable
``SPOTLAB_NATNET_PROBE`` (``HOST[:PORT]``, comma-separated).
"""

from __future__ import annotations

import os
import select
import socket
import time

from spotlab.drivers.base import DeviceInfo
from spotlab.drivers.natnet.wire import (
    NAT_DISCONNECT,
    NAT_SERVERINFO,
    NatNetFormatError,
    ServerInfo,
    connect_request,
    parse_server_info,
    request,
    split_packet,
)

#: Environment variable naming the addresses to probe (default ``127.0.0.1:1510``).
PROBE_ENV = "SPOTLAB_NATNET_PROBE"
DEFAULT_ADDRESS = "127.0.0.1:1510"
#: Seconds each address has to answer.
PROBE_TIMEOUT_S = 0.5


def probe_addresses() -> list[str]:
    """The ``HOST:PORT`` addresses to probe (``SPOTLAB_NATNET_PROBE`` or the default)."""
    text = os.environ.get(PROBE_ENV, "").strip() or DEFAULT_ADDRESS
    return [item.strip() for item in text.split(",") if item.strip()]


def ask_server_info(
    address: tuple[str, int], timeout: float = PROBE_TIMEOUT_S
) -> ServerInfo | None:
    """The server info of a NatNet server at ``address``, or None if none answers."""
    family = socket.AF_INET6 if ":" in address[0] else socket.AF_INET
    with socket.socket(family, socket.SOCK_DGRAM) as sock:
        try:
            sock.sendto(connect_request(), address)
        except OSError:
            return None
        end = time.monotonic() + timeout
        while (left := end - time.monotonic()) > 0:
            ready, _, _ = select.select([sock], [], [], left)
            if not ready:
                break
            try:
                data = sock.recv(65536)
            except OSError:  # nothing listens there (ICMP port unreachable)
                return None
            try:
                message_id, payload = split_packet(data)
                if message_id == NAT_SERVERINFO:
                    info = parse_server_info(payload)
                    sock.sendto(request(NAT_DISCONNECT), address)
                    return info
            except (NatNetFormatError, OSError):
                continue  # a frame, or not NatNet: wait for the server info
    return None


def detect_servers(addresses: list[tuple[str, int]]) -> list[DeviceInfo]:
    """The NatNet servers that answer at ``addresses`` ((host, command port) each)."""
    found: list[DeviceInfo] = []
    for host, port in addresses:
        info = ask_server_info((host, port))
        if info is None:
            continue
        major, minor = info.version
        app = ".".join(str(x) for x in info.app_version)
        mode = f"multicast {info.group}:{info.data_port}" if info.multicast else "unicast"
        found.append(
            DeviceInfo(
                family="natnet",
                port=f"{host}:{port}",
                description=f"NatNet {major}.{minor} server {info.name!r} (app {app}, {mode})",
                extra={
                    "natnet_version": [major, minor],
                    "app_version": list(info.app_version),
                    "clock_hz": info.clock_hz,
                    "multicast": info.multicast,
                    "data_port": info.data_port,
                },
            )
        )
    return found
