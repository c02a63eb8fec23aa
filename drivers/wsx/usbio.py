"""Finding and opening WSX hubs with pyusb: ports, backends, clear errors.

A port names where to look: ``wsxsim://HOST:PORT/SERIAL`` (a simulator, over
:class:`~spotlab.drivers.wsx.link.SocketBackend`) or ``usb[:VID:PID][:SERIAL]`` and
a bare ``SERIAL`` (libusb: the ``libusb-package`` wheel's library, else the
system's). Permission and ownership problems become one sentence naming the remedy.
"""

from __future__ import annotations

import errno
import re
from dataclasses import dataclass
from typing import Any

import usb.backend.libusb1
import usb.core
import usb.util

from spotlab.core.errors import ConfigurationError, DeviceError, DeviceNotFound
from spotlab.drivers.base import DeviceInfo
from spotlab.drivers.wsx.link import SCHEME, SocketBackend, parse_sim_address
from spotlab.drivers.wsx.protocol import PRODUCT_ID, VENDOR_ID

UDEV_HINT = (
    "install spotlab's udev rules (spotlab udev install: 60-spotlab.rules with "
    "61-spotlab-uaccess.rules, or 61-spotlab-plugdev.rules; docs/udev.md), then replug it"
)
_USB = re.compile(r"^usb(?::([0-9A-Fa-f]{4}):([0-9A-Fa-f]{4}))?(?::([\w.-]+))?$")


@dataclass(frozen=True)
class Target:
    """Where a hub is looked for: a simulator's socket, or libusb; a serial or any."""

    host: str = ""
    port: int = 0
    serial: str = ""

    @property
    def simulated(self) -> bool:
        return bool(self.host)

    def where(self) -> str:
        return f"{SCHEME}://{self.host}:{self.port}" if self.simulated else "USB"


def parse_port(port: str) -> Target:
    """The target of a driver port.

    Raises
    ------
    ConfigurationError
        For a malformed port or a VID:PID that is not the WSX hub's.
    """
    if port.startswith(f"{SCHEME}:"):
        host, number, serial = parse_sim_address(port)
        return Target(host, number, serial)
    m = _USB.match(port)
    if m:
        vid, pid, serial = m.groups()
        if vid is not None and (int(vid, 16), int(pid, 16)) != (VENDOR_ID, PRODUCT_ID):
            raise ConfigurationError(
                f"USB {vid.lower()}:{pid.lower()} is not a WSX hub "
                f"(the WSX hub is {VENDOR_ID:04x}:{PRODUCT_ID:04x})"
            )
        return Target(serial=serial or "")
    if re.fullmatch(r"[\w.-]+", port):
        return Target(serial=port)
    raise ConfigurationError(
        f"a WSX port is usb, usb:SERIAL, usb:1209:0010:SERIAL or {SCHEME}://HOST:PORT/SERIAL, "
        f"got {port!r}"
    )


def parse_ports(text: str | None) -> tuple[int, int, int, int] | None:
    """``8+8+8`` -> markers per strober port (4 ports); None for None."""
    if text is None:
        return None
    try:
        counts = [int(x) for x in str(text).replace(",", "+").split("+")]
    except ValueError:
        raise ConfigurationError(f"ports must be counts joined by '+', got {text!r}") from None
    if not 1 <= len(counts) <= 4 or min(counts) < 0:
        raise ConfigurationError(f"ports: 1-4 non-negative counts, got {text!r}")
    counts += [0] * (4 - len(counts))
    return (counts[0], counts[1], counts[2], counts[3])


def backend_for(target: Target) -> Any:
    """The pyusb backend that reaches ``target``."""
    if target.simulated:
        return SocketBackend(target.host, target.port)
    try:
        import libusb_package  # the wheel that brings libusb along

        backend = libusb_package.get_libusb1_backend()
    except ImportError:
        backend = usb.backend.libusb1.get_backend()
    if backend is None:
        raise DeviceNotFound("no libusb on this machine: pip install libusb-package")
    return backend


def _serial(dev: Any) -> str:
    try:
        return str(dev.serial_number or "")
    except (usb.core.USBError, ValueError) as exc:
        if isinstance(exc, ValueError) or exc.errno == errno.EACCES:
            raise DeviceError(
                f"no permission to open the WSX hub on bus {dev.bus} address {dev.address}: "
                + UDEV_HINT
            ) from None
        raise


def open_hub(target: Target, name: str) -> tuple[Any, str]:
    """Find the hub of ``target``, configure it and claim interface 0: (device, serial).

    Raises
    ------
    DeviceNotFound
        When no hub (with that serial) is there.
    DeviceError
        Without permission, or when another process holds it.
    """
    backend = backend_for(target)
    try:
        found = list(
            usb.core.find(find_all=True, idVendor=VENDOR_ID, idProduct=PRODUCT_ID, backend=backend)
            or []
        )
        devs = [(d, _serial(d)) for d in found]
    except usb.core.USBError as exc:
        _close_backend(backend)
        raise DeviceNotFound(f"{name}: no WSX hub at {target.where()}: {exc}") from None
    match = [(d, s) for d, s in devs if not target.serial or s == target.serial]
    for d, _ in devs:  # release the handles opened to read serial numbers
        if not match or d is not match[0][0]:
            usb.util.dispose_resources(d)
    if not match:
        _close_backend(backend)
        serial = f" with serial {target.serial}" if target.serial else ""
        seen = f" (found: {', '.join(s for _, s in devs)})" if devs else ""
        raise DeviceNotFound(
            f"{name}: no WSX hub (USB {VENDOR_ID:04x}:{PRODUCT_ID:04x}){serial} "
            f"at {target.where()}{seen}"
        )
    dev, serial = match[0]
    try:
        dev.set_configuration()
        usb.util.claim_interface(dev, 0)
    except usb.core.USBError as exc:
        release(dev)
        if exc.errno == errno.EBUSY:
            raise DeviceError(
                f"{name}: the WSX hub {serial} is held by another process (close it first)"
            ) from None
        if exc.errno == errno.EACCES:
            raise DeviceError(
                f"{name}: no permission to open the WSX hub {serial}: {UDEV_HINT}"
            ) from None
        raise DeviceNotFound(f"{name}: cannot open the WSX hub {serial}: {exc}") from None
    return dev, serial


def _close_backend(backend: Any) -> None:
    if isinstance(backend, SocketBackend):
        backend.close()


def release(dev: Any) -> None:
    """Release the interface and the handle (a hub that is gone is fine)."""
    if dev is None:
        return
    try:
        usb.util.release_interface(dev, 0)
    except (usb.core.USBError, ValueError):
        pass
    try:
        usb.util.dispose_resources(dev)
    except usb.core.USBError:
        pass
    _close_backend(dev._ctx.backend)


def detect(family: str) -> list[DeviceInfo]:
    """Hubs libusb sees (none when there is no libusb or no permission to list)."""
    try:
        backend = backend_for(Target())
        found = list(
            usb.core.find(find_all=True, idVendor=VENDOR_ID, idProduct=PRODUCT_ID, backend=backend)
            or []
        )
    except (DeviceNotFound, usb.core.USBError):
        return []
    out = []
    for d in found:
        try:
            serial = str(d.serial_number or "")
        except (usb.core.USBError, ValueError):
            serial = ""
        out.append(DeviceInfo(
            family, f"usb:{serial}" if serial else "usb",
            f"WSX hub, bus {d.bus} address {d.address}" + ("" if serial else " (no permission)"),
            serial, {"vid_pid": f"{VENDOR_ID:04x}:{PRODUCT_ID:04x}"},
        ))  # fmt: skip
    return out
