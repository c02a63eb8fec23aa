"""Real pyusb code above the simulated hub (``WsxSimBackend``, an ``IBackend``):
enumeration, strings, control, bulk and interrupt reads, timeouts, stalls and
``clear_halt``, unplug (``ENODEV``) and return with a new address."""

from __future__ import annotations

import errno

import pytest
import usb.core
import usb.util

from spotlab.simulators import wsx_wire as w
from spotlab.simulators.wsx_backend import WsxSimBackend
from spotlab.simulators.wsx_service import WsxSimOptions, build_device


def _find(backend: WsxSimBackend) -> usb.core.Device:
    dev = usb.core.find(idVendor=w.VID, idProduct=w.PID, backend=backend)
    assert dev is not None
    return dev


def test_pyusb_finds_reads_strings_and_streams() -> None:
    device = build_device(WsxSimOptions(sensors=2, markers=4, rate_hz=250))
    dev = _find(WsxSimBackend([device]))
    assert (dev.serial_number, dev.manufacturer, dev.product) == (
        "WSX00042", "spotlab", "WSX position sensor hub",
    )  # fmt: skip
    dev.set_configuration()
    usb.util.claim_interface(dev, 0)
    info = bytes(dev.ctrl_transfer(0xC0, w.REQ_INFO, 0, 0, 16))
    assert info[2] == 2
    with pytest.raises(usb.core.USBTimeoutError):
        dev.read(w.EP_FRAMES, 65536, 20)  # not streaming: nothing comes
    dev.ctrl_transfer(0x40, w.REQ_START, 0, 0, None)
    data = bytes(dev.read(w.EP_FRAMES, 65536, 500))
    size = 32 + 4 * (4 + 24 * 2) + 4
    assert data[:4] == b"WSXF" and len(data) % size == 0
    with pytest.raises(usb.core.USBError) as refused:
        dev.ctrl_transfer(0x40, w.REQ_SET_SETUP, 0, 0, w.encode_setup(w.Setup()))
    assert refused.value.errno == errno.EPIPE
    assert bytes(dev.ctrl_transfer(0xC0, w.REQ_STATUS, 0, 0, 16))[1] == w.E_BUSY
    usb.util.dispose_resources(dev)


def test_stall_clear_halt_unplug_and_return_with_a_new_address() -> None:
    device = build_device(WsxSimOptions(markers=4, rate_hz=250, faults="stall@0.05,unplug@0.2:0.2"))
    backend = WsxSimBackend([device])
    dev = _find(backend)
    address = dev.address
    dev.set_configuration()
    dev.ctrl_transfer(0x40, w.REQ_START, 0, 0, None)
    seen = []
    for _ in range(200):
        try:
            dev.read(w.EP_FRAMES, 65536, 50)
        except usb.core.USBTimeoutError:
            seen.append("timeout")
        except usb.core.USBError as exc:
            seen.append(errno.errorcode[exc.errno or 0])
            if exc.errno == errno.EPIPE:
                dev.clear_halt(w.EP_FRAMES)
                event = bytes(dev.read(w.EP_EVENTS, 16, 50))
                assert event[:6] == b"WSXE\x03\x00"
            if exc.errno == errno.ENODEV:
                break
    assert seen[:1] == ["EPIPE"] and seen[-1] == "ENODEV"
    assert usb.core.find(idVendor=w.VID, idProduct=w.PID, backend=backend) is None
    for _ in range(100):
        again = usb.core.find(idVendor=w.VID, idProduct=w.PID, backend=backend)
        if again is not None:
            break
        import time

        time.sleep(0.01)
    assert again is not None and again.address != address
    assert again.serial_number == "WSX00042"
    status = bytes(again.ctrl_transfer(0xC0, w.REQ_STATUS, 0, 0, 16))
    assert status[0] == 0  # power-up state: not streaming
