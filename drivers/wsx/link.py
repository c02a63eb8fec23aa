"""USB over a socket, host side: a pyusb backend that forwards every call (wsx.md §8).

``wsxsim://HOST:PORT/SERIAL`` names a device served by another process (``spotlab
sim wsx``). :class:`SocketBackend` implements ``usb.backend.IBackend``: pyusb's
``usb.core.find``, descriptors, strings, ``ctrl_transfer``, ``read`` and
``clear_halt`` run unchanged above it, as they do above libusb. Negative statuses
come back as the exceptions libusb's backend raises.
"""

from __future__ import annotations

import errno
import socket
import struct
import threading
from collections.abc import Iterator
from types import SimpleNamespace
from typing import Any
from urllib.parse import urlsplit

import usb.backend
import usb.core

from spotlab.core.errors import ConfigurationError

SCHEME = "wsxsim"
_ERRNO = {
    -1: errno.EIO, -3: errno.EACCES, -4: errno.ENODEV, -5: errno.ENOENT, -6: errno.EBUSY,
    -7: errno.ETIMEDOUT, -8: errno.EOVERFLOW, -9: errno.EPIPE,
}  # fmt: skip
_OP_LIST, _OP_OPEN, _OP_CLOSE, _OP_SET_CONFIG, _OP_CLAIM, _OP_RELEASE = 1, 2, 3, 4, 5, 6
_OP_CONTROL, _OP_READ, _OP_CLEAR_HALT = 7, 8, 10
_DEVICE_FIELDS = (
    "bLength bDescriptorType bcdUSB bDeviceClass bDeviceSubClass bDeviceProtocol "
    "bMaxPacketSize0 idVendor idProduct bcdDevice iManufacturer iProduct "
    "iSerialNumber bNumConfigurations"
).split()


def parse_sim_address(port: str) -> tuple[str, int, str]:
    """``wsxsim://HOST:PORT/SERIAL`` -> (host, port, serial; empty for any).

    Raises
    ------
    ConfigurationError
        If it is not such an address.
    """
    parts = urlsplit(port)
    try:
        number = parts.port
    except ValueError:
        number = None
    if parts.scheme != SCHEME or not parts.hostname or number is None:
        raise ConfigurationError(
            f"a simulated WSX hub is {SCHEME}://HOST:PORT/SERIAL, got {port!r}"
        )
    return parts.hostname, number, parts.path.strip("/")


def raise_status(status: int) -> int:
    """``status`` when not negative, else pyusb's exception for that libusb error."""
    if status >= 0:
        return status
    text = {-4: "No such device (it may have been disconnected)", -7: "Operation timed out",
            -8: "Overflow", -9: "Pipe error", -6: "Resource busy",
            -3: "Access denied (insufficient permissions)"}.get(status, "Other error")  # fmt: skip
    if status == -7:
        raise usb.core.USBTimeoutError(text, status, _ERRNO[status])
    raise usb.core.USBError(text, status, _ERRNO.get(status))


class _Dev:
    """A device as listed: bus, address, port and its raw descriptors."""

    def __init__(self, bus: int, address: int, port: int, device: bytes, config: bytes) -> None:
        self.bus, self.address, self.port = bus, address, port
        self.device, self.config = device, config


class SocketBackend(usb.backend.IBackend):
    """pyusb backend of the devices a ``spotlab sim wsx`` process serves.

    Parameters
    ----------
    host, port : str, int
        Where the simulator listens.
    timeout : float
        Seconds to connect; a request waits for its own USB timeout plus this.
    """

    def __init__(self, host: str, port: int, timeout: float = 2.0) -> None:
        super().__init__()
        self.host, self.port, self.timeout = host, port, timeout
        self._sock: socket.socket | None = None
        self._closed = False
        self._lock = threading.Lock()

    # -- the socket --------------------------------------------------------------------
    def _connect(self) -> socket.socket:
        if self._closed:
            raise usb.core.USBError("the WSX simulator link is closed", -4, errno.ENODEV)
        if self._sock is None:
            try:
                sock = socket.create_connection((self.host, self.port), timeout=self.timeout)
            except OSError as exc:
                raise usb.core.USBError(
                    f"no WSX simulator at {self.host}:{self.port}: {exc}", -4, errno.ENODEV
                ) from exc
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self._sock = sock
        return self._sock

    def _call(self, op: int, args: bytes = b"", wait_ms: int = 0) -> tuple[int, bytes]:
        with self._lock:
            sock = self._connect()
            sock.settimeout(self.timeout + wait_ms / 1000.0)
            try:
                sock.sendall(struct.pack("<IB", 1 + len(args), op) + args)
                head = self._recv(sock, 4)
                body = self._recv(sock, struct.unpack("<I", head)[0])
            except OSError as exc:
                self.close()
                raise usb.core.USBError(
                    f"WSX simulator link lost: {exc}", -4, errno.ENODEV
                ) from exc
        status = struct.unpack_from("<i", body)[0]
        return status, body[4:]

    @staticmethod
    def _recv(sock: socket.socket, n: int) -> bytes:
        buf = bytearray()
        while len(buf) < n:
            chunk = sock.recv(n - len(buf))
            if not chunk:
                raise ConnectionResetError("the simulator closed the link")
            buf += chunk
        return bytes(buf)

    def close(self) -> None:
        """Close the socket for good (a new backend connects again)."""
        self._closed = True
        if self._sock is not None:
            try:
                self._sock.close()
            finally:
                self._sock = None

    # -- IBackend ------------------------------------------------------------------------
    def enumerate_devices(self) -> Iterator[_Dev]:
        status, data = self._call(_OP_LIST)
        raise_status(status)
        pos = 1
        for _ in range(data[0] if data else 0):
            bus, address, port = data[pos : pos + 3]
            device = data[pos + 3 : pos + 21]
            n = struct.unpack_from("<H", data, pos + 21)[0]
            config = data[pos + 23 : pos + 23 + n]
            pos += 23 + n
            yield _Dev(bus, address, port, device, config)

    def get_device_descriptor(self, dev: _Dev) -> SimpleNamespace:
        values = struct.unpack("<BBHBBBBHHHBBBB", dev.device)
        return SimpleNamespace(
            **dict(zip(_DEVICE_FIELDS, values, strict=True)), bus=dev.bus, address=dev.address,
            port_number=dev.port, port_numbers=(dev.port,), speed=3,
        )  # fmt: skip

    def _walk(self, dev: _Dev) -> list[tuple[int, bytes]]:
        out, pos = [], 0
        while pos + 2 <= len(dev.config):
            n = dev.config[pos]
            if n < 2:
                break
            out.append((dev.config[pos + 1], dev.config[pos : pos + n]))
            pos += n
        return out

    def get_configuration_descriptor(self, dev: _Dev, config: int) -> SimpleNamespace:
        raw = next(d for t, d in self._walk(dev) if t == 2)
        c = struct.unpack("<BBHBBBBB", raw[:9])
        return SimpleNamespace(
            bLength=c[0], bDescriptorType=c[1], wTotalLength=c[2], bNumInterfaces=c[3],
            bConfigurationValue=c[4], iConfiguration=c[5], bmAttributes=c[6], bMaxPower=c[7],
            extra_descriptors=[],
        )  # fmt: skip

    def get_interface_descriptor(self, dev: _Dev, intf: int, alt: int, config: int) -> Any:
        raws = [d for t, d in self._walk(dev) if t == 4]
        i = struct.unpack("<BBBBBBBBB", raws[intf][:9])
        return SimpleNamespace(
            bLength=i[0], bDescriptorType=i[1], bInterfaceNumber=i[2], bAlternateSetting=i[3],
            bNumEndpoints=i[4], bInterfaceClass=i[5], bInterfaceSubClass=i[6],
            bInterfaceProtocol=i[7], iInterface=i[8], extra_descriptors=[],
        )  # fmt: skip

    def get_endpoint_descriptor(self, dev: _Dev, ep: int, intf: int, alt: int, config: int) -> Any:
        raws = [d for t, d in self._walk(dev) if t == 5]
        e = struct.unpack("<BBBBHB", raws[ep][:7])
        return SimpleNamespace(
            bLength=e[0], bDescriptorType=e[1], bEndpointAddress=e[2], bmAttributes=e[3],
            wMaxPacketSize=e[4], bInterval=e[5], bRefresh=0, bSynchAddress=0,
            extra_descriptors=[],
        )  # fmt: skip

    def open_device(self, dev: _Dev) -> _Dev:
        raise_status(self._call(_OP_OPEN, bytes([dev.address]))[0])
        return dev

    def close_device(self, dev_handle: _Dev) -> None:
        try:
            self._call(_OP_CLOSE)
        except usb.core.USBError:
            pass

    def set_configuration(self, dev_handle: _Dev, config_value: int) -> None:
        raise_status(self._call(_OP_SET_CONFIG, bytes([config_value]))[0])

    def get_configuration(self, dev_handle: _Dev) -> int:
        return 1

    def set_interface_altsetting(self, dev_handle: _Dev, intf: int, altsetting: int) -> None:
        return None

    def claim_interface(self, dev_handle: _Dev, intf: int) -> None:
        raise_status(self._call(_OP_CLAIM, bytes([intf]))[0])

    def release_interface(self, dev_handle: _Dev, intf: int) -> None:
        try:
            self._call(_OP_RELEASE, bytes([intf]))
        except usb.core.USBError:
            pass

    def ctrl_transfer(
        self, dev_handle: _Dev, bmRequestType: int, bRequest: int, wValue: int, wIndex: int,
        data: Any, timeout: int,
    ) -> int:  # fmt: skip
        is_in = bmRequestType & 0x80 != 0
        length = len(data)
        out = b"" if is_in else bytes(data)
        args = struct.pack("<BBHHHI", bmRequestType, bRequest, wValue, wIndex, length, timeout)
        status, got = self._call(_OP_CONTROL, args + out, timeout)
        raise_status(status)
        if is_in:
            data[: len(got)] = type(data)(data.typecode, got)
            return len(got)
        return status

    def _read(self, ep: int, buff: Any, timeout: int) -> int:
        status, got = self._call(_OP_READ, struct.pack("<BII", ep, len(buff), timeout), timeout)
        raise_status(status)
        buff[: len(got)] = type(buff)(buff.typecode, got)
        return len(got)

    def bulk_read(self, dev_handle: _Dev, ep: int, intf: int, buff: Any, timeout: int) -> int:
        return self._read(ep, buff, timeout)

    def intr_read(self, dev_handle: _Dev, ep: int, intf: int, buff: Any, timeout: int) -> int:
        return self._read(ep, buff, timeout)

    def clear_halt(self, dev_handle: _Dev, ep: int) -> None:
        raise_status(self._call(_OP_CLEAR_HALT, bytes([ep]))[0])

    def is_kernel_driver_active(self, dev_handle: _Dev, intf: int) -> bool:
        return False

    def detach_kernel_driver(self, dev_handle: _Dev, intf: int) -> None:
        return None

    def attach_kernel_driver(self, dev_handle: _Dev, intf: int) -> None:
        return None
