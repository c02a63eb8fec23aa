"""Finding MCS-1 devices of one family on this machine's serial ports (``VER:0`` probes)."""

from __future__ import annotations

import logging
import os
from collections.abc import Callable, Iterable

from serial.tools import list_ports

from spotlab.core.errors import ConfigurationError, DeviceError, ProtocolError
from spotlab.drivers.base import DeviceInfo
from spotlab.drivers.mcs1.link import SerialLink
from spotlab.drivers.mcs1.session import CommandChannel

log = logging.getLogger(__name__)

#: Builds a :class:`DeviceInfo` from a port and its ``VER:0`` reply text (raises
#: ``ProtocolError`` when the reply is not the family's).
InfoFromVersion = Callable[[str, str], DeviceInfo]


def hardware_ports() -> list[str]:
    """Serial ports the OS lists with hardware behind them.

    Ports whose hardware id is ``n/a`` (such as unused built-in ``ttyS`` ports) are left out.
    """
    return [p.device for p in list_ports.comports() if p.hwid and p.hwid != "n/a"]


def detect(
    family_code: str,
    device_info: InfoFromVersion,
    ports: Iterable[str | os.PathLike[str]] | None,
    timeout: float,
) -> list[DeviceInfo]:
    """Devices answering ``VER:0`` with ``family_code`` on ``ports``.

    Parameters
    ----------
    family_code : str
        The family's code (``"SPX"``), the first word of the ``VER:0`` reply.
    device_info : callable
        ``(port, reply text) -> DeviceInfo``.
    ports : iterable of str, optional
        Ports or URLs to probe; :func:`hardware_ports` by default.
    timeout : float
        Seconds to wait for each port's reset banner and reply.

    Returns
    -------
    list of DeviceInfo
        One per device that answered; each is left reset (9600 baud, not streaming).
        Ports that cannot be opened (busy, no permission) are skipped.
    """
    if ports is None:
        ports = hardware_ports()
    found = []
    for port in ports:
        info = probe(os.fspath(port), timeout, family_code, device_info)
        if info is not None:
            found.append(info)
    return found


def probe(
    port: str, timeout: float, family_code: str, device_info: InfoFromVersion
) -> DeviceInfo | None:
    """Reset the device on ``port`` and ask ``VER:0``; ``None`` unless it is of the family."""
    link = SerialLink(port)
    try:
        link.open()
    except (DeviceError, ConfigurationError) as exc:
        log.debug("detect: skipping %s: %s", port, exc)
        return None
    try:
        channel = CommandChannel(link, timeout)
        channel.reset(timeout)
        reply = channel.transact("VER", "0", data_prefix=family_code)
        info = device_info(port, reply.text)
    except (DeviceError, ProtocolError, ConfigurationError) as exc:
        log.debug("detect: no %s device on %s: %s", family_code, port, exc)
        return None
    finally:
        link.close()
    return info
