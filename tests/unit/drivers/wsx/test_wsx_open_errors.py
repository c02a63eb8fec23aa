"""Opening a hub that another process holds, or without permission: one sentence each,
the second naming the udev rules to install (pyusb above the simulated backend)."""

from __future__ import annotations

import errno
from typing import Any

import pytest
import usb.core

from spotlab.core.errors import DeviceError
from spotlab.drivers.wsx import usbio
from spotlab.simulators.wsx_backend import WsxSimBackend
from spotlab.simulators.wsx_service import WsxSimOptions, build_device


class _Busy(WsxSimBackend):
    def claim_interface(self, dev_handle: Any, intf: int) -> None:
        raise usb.core.USBError("Resource busy", -6, errno.EBUSY)


class _NoAccess(WsxSimBackend):
    def open_device(self, dev: Any) -> Any:
        raise usb.core.USBError("Access denied (insufficient permissions)", -3, errno.EACCES)


@pytest.mark.parametrize(
    ("backend", "says"),
    [
        (_Busy, "is held by another process"),
        (_NoAccess, "no permission to open the WSX hub on bus 1 address 7: install spotlab's udev"),
    ],
)
def test_one_clear_sentence(
    backend: type[WsxSimBackend], says: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    device = build_device(WsxSimOptions())
    monkeypatch.setattr(usbio, "backend_for", lambda target: backend([device]))
    with pytest.raises(DeviceError) as info:
        usbio.open_hub(usbio.Target(serial="WSX00042"), "wsx")
    assert says in str(info.value) and "\n" not in str(info.value)
    if backend is _NoAccess:
        assert "60-spotlab.rules" in str(info.value)
