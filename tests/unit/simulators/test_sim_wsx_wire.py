"""The device side of the WSX bytes against the golden vectors of docs/protocols/wsx.md."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest

from spotlab.simulators import wsx_wire as w
from spotlab.simulators.wsx_device import WsxDevice
from spotlab.simulators.wsx_scene import WsxScene
from spotlab.testing.golden import golden_vector

SPEC = Path(__file__).resolve().parents[3] / "docs" / "protocols" / "wsx.md"
SETUP_24 = w.Setup(24, (8, 8, 8, 0), 350, 4_600_000, 176_923, 80, 30, 160, w.FLAG_FULL_RAW)


def _golden(name: str) -> bytes:
    return golden_vector(SPEC, name)


def test_descriptors_match() -> None:
    assert w.device_descriptor() == _golden("Device descriptor")
    assert w.configuration_descriptor() == _golden("Configuration descriptor")
    assert w.string_descriptor(3, "WSX00042") == _golden("Serial string")


def test_records_match() -> None:
    assert w.encode_info(3) == _golden("Information")
    assert w.encode_setup(SETUP_24) == _golden("Set-up")
    assert w.encode_status(True, 0, 0, 1000, 0, 123_456) == _golden("Status")
    assert w.encode_status(False, 0x24, 0, 0, 0, 2000) == _golden("Status after the refused set-up")
    rot = np.stack([np.eye(3)] * 3)
    t = np.array([[450.0, 0.0, 3000.0], [0.0, 0.0, 3000.0], [-450.0, 0.0, 3000.0]])
    cal = w.encode_calibration(0, [0, 1, 0], [1750.0] * 3, [1024.0] * 3, rot, t)
    assert cal == _golden("Calibration")


def test_set_up_checks_follow_the_bounds() -> None:
    assert w.parse_setup(_golden("Set-up")) == (SETUP_24, w.E_NONE)
    assert w.parse_setup(_golden("Refused set-up"))[1] == w.E_FRAME_RATE
    bad = {
        w.E_MARKERS: w.Setup(markers=0, ports=(0, 0, 0, 0)),
        w.E_PORTS: w.Setup(markers=8, ports=(4, 0, 0, 0)),
        w.E_MARKER_RATE: w.Setup(marker_rate_mhz=4_700_000),
        w.E_DUTY: w.Setup(duty_permille=900),
        w.E_VOLTAGE: w.Setup(voltage_dv=130),
        w.E_GAIN: w.Setup(gain=0),
        w.E_FLAGS: w.Setup(flags=0x10),
    }
    for code, setup in bad.items():
        assert w.parse_setup(w.encode_setup(setup))[1] == code
    assert w.parse_setup(b"\0" * 31)[1] == w.E_LENGTH


def test_frame_and_event_match() -> None:
    centroid = np.array([[[1024.5, 1000.25, -1.0]], [[1100.0, np.nan, 980.75]]])
    peak = np.array([[[2000, 1800, 4095]], [[1500, 0, 1200]]])
    code = np.array([[[0, 0, 3]], [[0, 2, 10]]])
    fire = np.array([38_043, 255_435])
    frame = w.encode_frame(1234, 5_000_000_000, 0, fire, centroid, peak, code)
    assert frame == _golden("Frame")
    assert w.encode_event(w.EV_OVERFLOW, 1234, 3) == _golden("Event")


def test_link_messages_match() -> None:
    status = w.encode_status(True, 0, 0, 1000, 0, 123_456)
    assert w.reply(16, status) == _golden("Link STATUS reply")
    assert w.reply(-9) == _golden("Link stall reply")
    req = _golden("Link STATUS request")
    assert struct.unpack_from("<IB", req) == (len(req) - 4, w.OP_CONTROL)
    assert w.CONTROL.unpack_from(req, 5) == (0xC0, w.REQ_STATUS, 0, 0, 16, 1000)
    read = _golden("Link READ request")
    assert w.READ.unpack_from(read, 5) == (w.EP_FRAMES, 16384, 100)


@pytest.mark.parametrize("name", ["Set-up", "Refused set-up"])
def test_the_device_answers_set_ups_as_the_spec_says(name: str) -> None:
    dev = WsxDevice(WsxScene(3, 24), "WSX00042", w.Setup())
    status, _ = dev.control(0, 0x40, w.REQ_SET_SETUP, 0, 0, _golden(name), 0)
    _, record = dev.control(0, 0xC0, w.REQ_STATUS, 0, 0, b"", 16)
    if name == "Set-up":
        assert status == 32 and record[1] == 0
    else:
        assert status == -9 and record[1] == 0x24
