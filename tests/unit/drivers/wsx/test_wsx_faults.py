"""The USB fault matrix (issue 17): stall, timeout, short packet, babble, unplug and
return, a refused set-up. The driver talks pyusb over the socket link to a simulator
served in this process; each fault is detected, counted, and streaming goes on."""

from __future__ import annotations

import time
from collections.abc import Iterator

import pytest

from spotlab.core.errors import ConfigurationError, DeviceNotFound
from spotlab.drivers.wsx import WsxDriver
from spotlab.simulators.wsx_service import WsxServer, WsxSimOptions, serve_wsx


@pytest.fixture
def faulty() -> Iterator[WsxServer]:
    faults = "stall@0.3,short@0.6,babble@0.8,timeout@1.0:0.7,unplug@2.0:0.4"
    server = serve_wsx(WsxSimOptions(markers=6, marker_rate_hz=2500, rate_hz=200, faults=faults))
    yield server
    server.stop()


def test_every_fault_is_detected_counted_and_streaming_goes_on(faulty: WsxServer) -> None:
    driver = WsxDriver(faulty.address, silence_timeout=0.3)
    driver.start()
    seqs = []
    try:
        t0 = time.monotonic()
        while time.monotonic() - t0 < 3.3:
            block = driver.recv(0.2)
            if block is not None:
                seqs.extend(block.seq.tolist())
    finally:
        driver.close()
    faults = driver.usb_faults
    assert faults["stalls"] == 1 and faults["short"] == 1 and faults["babble"] == 1
    assert faults["timeouts"] >= 1 and faults["unplugs"] == 1
    assert driver.stats.reconnects == 1
    assert driver.stats.device_dropped + driver.stats.lost_frames > 0
    assert seqs == sorted(seqs) and len(set(seqs)) == len(seqs)
    after = [s for s in seqs if s > max(seqs) - 50]
    assert len(after) == 50  # frames again, in order, after the unplug


def test_a_set_up_the_bounds_refuse_names_the_device_error() -> None:
    server = serve_wsx(WsxSimOptions(markers=24, marker_rate_hz=4600))
    try:
        driver = WsxDriver(server.address, rate_hz=200.0)
        with pytest.raises(ConfigurationError, match=r"error 0x24 \(frame rate"):
            driver.start()
        assert driver.usb_faults["refused"] == 1
        driver.close()
        ok = WsxDriver(server.address, rate_hz=176.9, ports="8+8+8")
        ok.start()
        assert ok.recv(1.0) is not None
        ok.close()
    finally:
        server.stop()


def test_a_serial_that_is_not_there() -> None:
    server = serve_wsx(WsxSimOptions())
    try:
        address = server.address.rsplit("/", 1)[0] + "/WSX99999"
        with pytest.raises(DeviceNotFound, match=r"serial WSX99999.*found: WSX00042"):
            WsxDriver(address).start()
    finally:
        server.stop()
