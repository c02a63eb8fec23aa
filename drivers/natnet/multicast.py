"""Receiving NatNet frames sent to a multicast group (docs/protocols/natnet.md §2)."""

from __future__ import annotations

import contextlib
import ipaddress
import socket

from spotlab.core.errors import ConfigurationError


def check_group(value: str | None) -> str | None:
    """``None``, ``"off"`` or an IPv4 multicast address (224.0.0.0/4), as given.

    Raises
    ------
    ConfigurationError
        If ``value`` is none of these.
    """
    if value is None or value == "off":
        return value
    try:
        address = ipaddress.IPv4Address(value)
    except ValueError:
        address = None
    if address is None or not address.is_multicast:
        raise ConfigurationError(
            f"multicast takes an IPv4 group address (224.0.0.0-239.255.255.255) or off, "
            f"got {value!r}"
        )
    return value


def local_address(server: tuple[str, int]) -> str:
    """This host's IPv4 address on the interface that routes to ``server`` (no packet sent)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        try:
            probe.connect(server)
        except OSError:
            return "0.0.0.0"  # noqa: S104 - INADDR_ANY: the system picks the interface
        return str(probe.getsockname()[0])


def join_group(group: str, port: int, interface: str) -> socket.socket:
    """A non-blocking UDP socket on ``port`` that has joined ``group`` on ``interface``.

    The socket binds the group address where the system allows it (Linux, macOS:
    only the group's datagrams come in), else any address; ``SO_REUSEADDR`` lets
    several clients on one host receive the same stream.
    """
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        if hasattr(socket, "SO_REUSEPORT"):
            with contextlib.suppress(OSError):
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEPORT, 1)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
        try:
            sock.bind((group, port))
        except OSError:
            sock.bind(("", port))
        membership = socket.inet_aton(group) + socket.inet_aton(interface)
        sock.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP, membership)
        sock.setblocking(False)
    except OSError:
        sock.close()
        raise
    return sock
