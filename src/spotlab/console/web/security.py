"""Who may reach the console: loopback by default, a token for any other address.

Imports nothing but the standard library, so that ``spotlab console`` refuses a bad
``--host``/``--token`` before it loads the web server.
"""

from __future__ import annotations

import ipaddress

from spotlab.processing.errors import InputError

__all__ = ["check_access", "is_loopback"]


def is_loopback(host: str) -> bool:
    """Whether ``host`` names this machine only (``localhost``, 127.x, ::1)."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def check_access(host: str, token: str | None) -> None:
    """InputError unless ``host`` is loopback or a non-empty ``token`` is given."""
    if token is not None and not token:
        raise InputError("--token must not be empty")
    if not is_loopback(host) and token is None:
        raise InputError(
            f"--host {host} serves beyond this machine: give --token T (the page and API "
            "then need ?token=T or 'Authorization: Bearer T')"
        )
