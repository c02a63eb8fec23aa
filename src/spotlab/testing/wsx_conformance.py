"""Conformance suite of a WSX hub (docs/protocols/wsx.md): the simulator in CI, a hub on
a bench with ``pytest tests/conformance/test_wsx.py --hw wsx=SERIAL``.

Subclass :class:`WsxConformance` and provide a ``wsx_port`` fixture yielding the
driver port (``usb:SERIAL`` or ``wsxsim://HOST:PORT/SERIAL``). Every assertion is one
a real hub must satisfy: descriptors and strings, the information record, set-ups
outside the bounds refused with their codes (and the set-up in force kept), the
factory calibration well formed, frames numbered one by one at the frame period with
markers fired in order. The tests leave the hub stopped, with the set-up it had.
Nothing compares with a simulator's truth.
"""

from __future__ import annotations

import errno
import re
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import replace
from typing import Any

import numpy as np
import pytest
import usb.core
import usb.util

from spotlab.drivers.wsx import WsxDriver
from spotlab.drivers.wsx.protocol import (
    CALIBRATION,
    EP_EVENTS,
    EP_FRAMES,
    GET_SETUP,
    INFO,
    SET_SETUP,
    STATUS,
    Info,
    Setup,
    Status,
    parse_calibration,
)
from spotlab.drivers.wsx.usbio import open_hub, parse_port, release
from spotlab.testing.streaming import collect


@contextmanager
def hub(port: str) -> Iterator[Any]:
    """The hub of ``port`` opened with pyusb (interface 0 claimed), released after."""
    dev, _ = open_hub(parse_port(port), "wsx")
    try:
        yield dev
    finally:
        release(dev)


def refused_code(dev: Any, setup: Setup) -> int:
    """Send ``setup``; the device's error code if it stalled, else 0."""
    try:
        dev.ctrl_transfer(0x40, SET_SETUP, 0, 0, setup.encode(), 1000)
    except usb.core.USBError as exc:
        assert exc.errno == errno.EPIPE, exc
        return Status.decode(bytes(dev.ctrl_transfer(0xC0, STATUS, 0, 0, 16, 1000))).last_error
    return 0


class WsxConformance:
    """Tests every WSX hub passes; needs a ``wsx_port`` fixture."""

    def test_descriptors_and_strings(self, wsx_port: str) -> None:
        with hub(wsx_port) as dev:
            assert (dev.idVendor, dev.idProduct, dev.bDeviceClass) == (0x1209, 0x0010, 0xFF)
            assert re.fullmatch(r"WSX\d{5}", dev.serial_number or "")
            intf = dev.get_active_configuration()[(0, 0)]
            eps = {e.bEndpointAddress: usb.util.endpoint_type(e.bmAttributes) for e in intf}
            assert eps == {
                EP_FRAMES: usb.util.ENDPOINT_TYPE_BULK, EP_EVENTS: usb.util.ENDPOINT_TYPE_INTR,
            }  # fmt: skip

    def test_information_and_calibration_are_well_formed(self, wsx_port: str) -> None:
        with hub(wsx_port) as dev:
            info = Info.decode(bytes(dev.ctrl_transfer(0xC0, INFO, 0, 0, 16, 1000)))
            assert (info.ccds, info.pixels, info.ports) == (3, 2048, 4)
            assert 1 <= info.sensors <= 8 and info.max_markers <= 512 and info.clock_hz > 0
            for s in range(info.sensors):
                raw = bytes(dev.ctrl_transfer(0xC0, CALIBRATION, 0, s, 188, 1000))
                for ccd in parse_calibration(raw, s):
                    R = np.asarray(ccd["R"])
                    assert np.allclose(R @ R.T, np.eye(3), atol=1e-5)
                    assert ccd["focal"] > 0 and 0 <= ccd["principal"] < info.pixels
            assert refused_code_of_missing_sensor(dev, info.sensors) == 0x2A

    @pytest.mark.parametrize(
        ("change", "code"),
        [
            ({"markers": 0, "ports": (0, 0, 0, 0)}, 0x21),
            ({"ports": (1, 0, 0, 0)}, 0x22),
            ({"marker_rate_mhz": 4_700_000}, 0x23),
            ({"frame_rate_mhz": 0}, 0x24),
            ({"frame_rate_mhz": 10_000_000}, 0x24),
            ({"duty_permille": 900}, 0x25),
            ({"voltage_dv": 60}, 0x26),
            ({"gain": 0}, 0x28),
            ({"flags": 0x80}, 0x29),
        ],
    )
    def test_set_ups_outside_the_bounds_are_refused(
        self, wsx_port: str, change: dict[str, Any], code: int
    ) -> None:
        with hub(wsx_port) as dev:
            before = bytes(dev.ctrl_transfer(0xC0, GET_SETUP, 0, 0, 32, 1000))
            current = Setup.decode(before)
            if change.get("ports") == (1, 0, 0, 0) and current.markers == 1:
                change = {"ports": (2, 0, 0, 0)}
            assert refused_code(dev, replace(current, **change)) == code
            assert bytes(dev.ctrl_transfer(0xC0, GET_SETUP, 0, 0, 32, 1000)) == before

    def test_frames_come_one_by_one_at_the_period(self, wsx_port: str) -> None:
        driver = WsxDriver(wsx_port, rate_hz=100.0, marker_rate_hz=2500.0)
        driver.start()
        try:
            block = collect(driver, 1.5)
            with pytest.raises(usb.core.USBError):  # no set-up while streaming
                driver.dev.ctrl_transfer(0x40, SET_SETUP, 0, 0, driver.setup.encode(), 1000)
        finally:
            driver.close()
        assert np.all(np.diff(block.seq) == 1) and driver.stats.lost_frames == 0
        period = np.diff(block.ticks) / driver.spec.tick_hz
        assert np.allclose(period, 0.01, atol=2e-5)
        fire = block.data[0, :, 0, 2]
        assert np.all(np.diff(fire) > 0) and fire[-1] < 0.01 * driver.spec.tick_hz
        assert np.allclose(np.diff(fire), driver.spec.tick_hz / 2500.0, rtol=1e-3)


def refused_code_of_missing_sensor(dev: Any, sensors: int) -> int:
    """The code of a ``CALIBRATION`` request for a sensor the hub does not have."""
    try:
        dev.ctrl_transfer(0xC0, CALIBRATION, 0, sensors, 188, 1000)
    except usb.core.USBError:
        return Status.decode(bytes(dev.ctrl_transfer(0xC0, STATUS, 0, 0, 16, 1000))).last_error
    return 0


__all__ = ["WsxConformance", "hub", "refused_code"]
