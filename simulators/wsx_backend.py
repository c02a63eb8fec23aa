"""Simulated WSX hubs as a pyusb backend (``usb.backend.IBackend``), in process.

``usb.core.find(backend=WsxSimBackend([device]))`` finds the hubs; every pyusb call
above (descriptors, strings, configuration, claim, control, bulk and interrupt
reads, ``clear_halt``) reaches :class:`~spotlab.simulators.wsx_device.WsxDevice`,
and its statuses come back as pyusb's exceptions (``USBTimeoutError`` for a timeout,
``USBError`` with ``errno`` ``EPIPE``, ``EOVERFLOW`` or ``ENODEV``). pyusb is needed
(the ``usb`` extra).
"""

from __future__ import annotations

import errno
import struct
from collections.abc import Iterator, Sequence
from types import SimpleNamespace
from typing import Any

import usb.backend
import usb.core

from spotlab.simulators import wsx_wire as w
from spotlab.simulators.wsx_device import WsxDevice

_ERRNO = {
    -1: errno.EIO, -3: errno.EACCES, -4: errno.ENODEV, -5: errno.ENOENT, -6: errno.EBUSY,
    -7: errno.ETIMEDOUT, -8: errno.EOVERFLOW, -9: errno.EPIPE,
}  # fmt: skip
_TEXT = {
    -1: "Input/Output Error", -3: "Access denied (insufficient permissions)",
    -4: "No such device (it may have been disconnected)", -5: "Entity not found",
    -6: "Resource busy", -7: "Operation timed out", -8: "Overflow", -9: "Pipe error",
}  # fmt: skip


def check(status: int) -> int:
    """``status`` if not negative, else the pyusb exception libusb's backend raises."""
    if status >= 0:
        return status
    if status == -7:
        raise usb.core.USBTimeoutError(_TEXT[status], status, _ERRNO[status])
    raise usb.core.USBError(_TEXT.get(status, "Other error"), status, _ERRNO.get(status))


def device_fields(raw: bytes, bus: int, address: int, port: int) -> SimpleNamespace:
    """A device descriptor object pyusb reads, from its 18 bytes."""
    names = (
        "bLength bDescriptorType bcdUSB bDeviceClass bDeviceSubClass bDeviceProtocol "
        "bMaxPacketSize0 idVendor idProduct bcdDevice iManufacturer iProduct "
        "iSerialNumber bNumConfigurations"
    ).split()
    values = struct.unpack("<BBHBBBBHHHBBBB", raw[:18])
    return SimpleNamespace(
        **dict(zip(names, values, strict=True)), bus=bus, address=address,
        port_number=port, port_numbers=(port,), speed=3,
    )  # fmt: skip


def config_fields(raw: bytes) -> tuple[SimpleNamespace, SimpleNamespace, list[SimpleNamespace]]:
    """Configuration, interface and endpoint descriptor objects of a configuration."""
    c = struct.unpack_from("<BBHBBBBB", raw, 0)
    cfg = SimpleNamespace(
        bLength=c[0], bDescriptorType=c[1], wTotalLength=c[2], bNumInterfaces=c[3],
        bConfigurationValue=c[4], iConfiguration=c[5], bmAttributes=c[6], bMaxPower=c[7],
        extra_descriptors=[],
    )  # fmt: skip
    i = struct.unpack_from("<BBBBBBBBB", raw, 9)
    intf = SimpleNamespace(
        bLength=i[0], bDescriptorType=i[1], bInterfaceNumber=i[2], bAlternateSetting=i[3],
        bNumEndpoints=i[4], bInterfaceClass=i[5], bInterfaceSubClass=i[6],
        bInterfaceProtocol=i[7], iInterface=i[8], extra_descriptors=[],
    )  # fmt: skip
    eps = []
    for k in range(intf.bNumEndpoints):
        e = struct.unpack_from("<BBBBHB", raw, 18 + 7 * k)
        eps.append(SimpleNamespace(
            bLength=e[0], bDescriptorType=e[1], bEndpointAddress=e[2], bmAttributes=e[3],
            wMaxPacketSize=e[4], bInterval=e[5], bRefresh=0, bSynchAddress=0,
            extra_descriptors=[],
        ))  # fmt: skip
    return cfg, intf, eps


class _Ref:
    """A device as enumerated: the hub and the generation it had then."""

    def __init__(self, device: WsxDevice) -> None:
        self.device, self.generation = device, device.generation
        self.address = device.address


class WsxSimBackend(usb.backend.IBackend):
    """pyusb backend over simulated hubs."""

    def __init__(self, devices: Sequence[WsxDevice]) -> None:
        super().__init__()
        self.devices = list(devices)

    def enumerate_devices(self) -> Iterator[_Ref]:
        for d in self.devices:
            if d.present(d.generation):
                yield _Ref(d)

    def get_device_descriptor(self, dev: _Ref) -> SimpleNamespace:
        d = dev.device
        return device_fields(w.device_descriptor(), d.bus, dev.address, d.port)

    def get_configuration_descriptor(self, dev: _Ref, config: int) -> SimpleNamespace:
        return config_fields(w.configuration_descriptor())[0]

    def get_interface_descriptor(
        self, dev: _Ref, intf: int, alt: int, config: int
    ) -> SimpleNamespace:
        return config_fields(w.configuration_descriptor())[1]

    def get_endpoint_descriptor(
        self, dev: _Ref, ep: int, intf: int, alt: int, config: int
    ) -> SimpleNamespace:
        return config_fields(w.configuration_descriptor())[2][ep]

    def open_device(self, dev: _Ref) -> _Ref:
        check(0 if dev.device.present(dev.generation) else -4)
        return dev

    def close_device(self, dev_handle: _Ref) -> None:
        return None

    def set_configuration(self, dev_handle: _Ref, config_value: int) -> None:
        check(0 if dev_handle.device.present(dev_handle.generation) else -4)

    def get_configuration(self, dev_handle: _Ref) -> int:
        return 1

    def set_interface_altsetting(self, dev_handle: _Ref, intf: int, altsetting: int) -> None:
        return None

    def claim_interface(self, dev_handle: _Ref, intf: int) -> None:
        check(0 if dev_handle.device.present(dev_handle.generation) else -4)

    def release_interface(self, dev_handle: _Ref, intf: int) -> None:
        return None

    def ctrl_transfer(
        self, dev_handle: _Ref, bmRequestType: int, bRequest: int, wValue: int, wIndex: int,
        data: Any, timeout: int,
    ) -> int:  # fmt: skip
        is_in = bmRequestType & 0x80 != 0
        length = len(data) if is_in else 0
        out = b"" if is_in else bytes(data)
        status, got = dev_handle.device.control(
            dev_handle.generation, bmRequestType, bRequest, wValue, wIndex, out, length
        )
        check(status)
        if is_in:
            data[: len(got)] = type(data)(data.typecode, got)
            return len(got)
        return status

    def _read(self, dev_handle: _Ref, ep: int, buff: Any, timeout: int) -> int:
        status, got = dev_handle.device.read(dev_handle.generation, ep, len(buff), timeout)
        check(status)
        buff[: len(got)] = type(buff)(buff.typecode, got)
        return len(got)

    def bulk_read(self, dev_handle: _Ref, ep: int, intf: int, buff: Any, timeout: int) -> int:
        return self._read(dev_handle, ep, buff, timeout)

    def intr_read(self, dev_handle: _Ref, ep: int, intf: int, buff: Any, timeout: int) -> int:
        return self._read(dev_handle, ep, buff, timeout)

    def clear_halt(self, dev_handle: _Ref, ep: int) -> None:
        check(dev_handle.device.clear_halt(dev_handle.generation, ep))

    def is_kernel_driver_active(self, dev_handle: _Ref, intf: int) -> bool:
        return False

    def detach_kernel_driver(self, dev_handle: _Ref, intf: int) -> None:
        return None

    def attach_kernel_driver(self, dev_handle: _Ref, intf: int) -> None:
        return None
