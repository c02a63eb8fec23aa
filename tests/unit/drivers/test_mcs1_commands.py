"""MCS-1 commands and replies: golden vectors of mcs1.md §6 and selspot.md §5, error mapping."""

from __future__ import annotations

import logging

import pytest
from _spx_wire import line

from spotlab.core.errors import BandwidthError, ConfigurationError, DeviceError, ProtocolError
from spotlab.drivers.mcs1.commands import (
    BANNER,
    BAUD_CODES,
    ERROR_MEANINGS,
    DeviceBandwidthError,
    DeviceConfigurationError,
    check_line,
    encode_command,
    parse_conf,
    parse_reply,
)
from spotlab.drivers.mcs1.session import find_reply


def test_crc_check_value() -> None:
    from spotlab.core.crc import crc16

    assert crc16(b"123456789") == 0x29B1


@pytest.mark.parametrize(
    ("verb", "args", "wire"),
    [
        ("VER", "0", "56 45 52 3A 30 46 37 43 31 0D"),
        ("COMM", "8", "43 4F 4D 4D 3A 38 38 42 39 32 0D"),
        ("RATE", "200000", "52 41 54 45 3A 32 30 30 30 30 30 38 45 43 36 0D"),
        ("START", "", "53 54 41 52 54 3A 35 31 42 34 0D"),
        ("STOP", "", "53 54 4F 50 3A 46 44 31 43 0D"),
        ("CAMS", "2", "43 41 4D 53 3A 32 42 44 31 32 0D"),
    ],
)
def test_golden_commands_hex(verb: str, args: str, wire: str) -> None:
    assert encode_command(verb, args) == bytes.fromhex(wire)


@pytest.mark.parametrize(
    ("verb", "args", "wire"),
    [
        ("VER", "0", b"VER:0F7C1\r"),
        ("COMM", "8", b"COMM:88B92\r"),
        ("RATE", "200000", b"RATE:2000008EC6\r"),
        ("START", "", b"START:51B4\r"),
        ("STOP", "", b"STOP:FD1C\r"),
        ("CONF", "", b"CONF:621B\r"),
        ("CAMS", "2", b"CAMS:2BD12\r"),
        ("LEDT", "008005C01140", b"LEDT:008005C01140E8FF\r"),
        ("SLOT", "100", b"SLOT:1000B9E\r"),
        ("BGND", "1", b"BGND:1587B\r"),
        ("AGC", "1,160", b"AGC:1,1608496\r"),
    ],
)
def test_golden_commands_text(verb: str, args: str, wire: bytes) -> None:
    assert encode_command(verb, args) == wire


def test_golden_banner() -> None:
    assert BANNER == bytes.fromhex("52 45 53 45 54 37 44 42 32 0D")
    assert check_line(BANNER) == "RESET"


def test_golden_replies() -> None:
    okay = parse_reply(bytes.fromhex("4F 4B 41 59 32 36 43 46 0D"))
    assert (okay.kind, okay.text, okay.code) == ("okay", "OKAY", None)
    e80 = parse_reply(bytes.fromhex("45 52 52 4F 52 38 30 43 46 35 33 0D"))
    assert (e80.kind, e80.text, e80.code) == ("error", "ERROR80", 0x80)
    e04 = parse_reply(bytes.fromhex("45 52 52 4F 52 30 34 30 36 37 45 0D"))
    assert (e04.kind, e04.code) == ("error", 0x04)
    t = parse_reply(b"TIME 0001E240 0001E2A4E2F2\r", data_prefix="TIME")
    assert (t.kind, t.text) == ("data", "TIME 0001E240 0001E2A4")
    v = parse_reply(b"SPX 1.0 SIM00042 4 128C2DE\r", data_prefix="SPX")
    assert (v.kind, v.text) == ("data", "SPX 1.0 SIM00042 4 128")


def test_baud_table() -> None:
    assert BAUD_CODES[9600] == 0 and BAUD_CODES[2_000_000] == 8 and BAUD_CODES[3_000_000] == 9
    assert sorted(BAUD_CODES.values()) == list(range(10))


def test_encode_rejects_non_ascii() -> None:
    with pytest.raises(ConfigurationError):
        encode_command("CAMS", "é")
    with pytest.raises(ConfigurationError):
        encode_command("CA:MS", "1")


@pytest.mark.parametrize("code", sorted(ERROR_MEANINGS))
def test_every_error_code_maps_to_device_error_with_meaning(code: int) -> None:
    reply = parse_reply(line(f"ERROR{code:02X}"))
    with pytest.raises(DeviceError) as info:
        reply.raise_for_error("CAMS:9")
    assert info.value.code == code
    assert ERROR_MEANINGS[code] in str(info.value)
    assert "CAMS:9" in str(info.value)
    assert f"ERROR{code:02X}" in str(info.value)


def test_error80_is_bandwidth_and_device_error() -> None:
    with pytest.raises(DeviceBandwidthError) as info:
        parse_reply(b"ERROR80CF53\r").raise_for_error("START:")
    assert isinstance(info.value, BandwidthError)
    assert isinstance(info.value, DeviceError)
    assert "bandwidth exceeded" in str(info.value)


@pytest.mark.parametrize("code", [0x23, 0x81, 0x82])
def test_configuration_refusals_are_configuration_errors(code: int) -> None:
    with pytest.raises(DeviceConfigurationError) as info:
        parse_reply(line(f"ERROR{code:02X}")).raise_for_error("LEDT:")
    assert isinstance(info.value, ConfigurationError)


def test_unknown_error_code_is_named() -> None:
    with pytest.raises(DeviceError, match="unknown error code") as info:
        parse_reply(line("ERROR99")).raise_for_error("X:")
    assert info.value.code == 0x99


def test_warning_is_logged_not_raised(caplog: pytest.LogCaptureFixture) -> None:
    reply = parse_reply(line("WARN83"))
    assert reply.kind == "warn" and reply.code == 0x83
    with caplog.at_level(logging.WARNING):
        assert reply.raise_for_error("START:") is reply
    assert "FIFO overflow" in caplog.text


def test_okay_passes() -> None:
    reply = parse_reply(line("OKAY"))
    assert reply.raise_for_error("CAMS:1") is reply


@pytest.mark.parametrize(
    "raw",
    [
        b"OKAY26CE\r",  # CRC off by one
        b"OKAY26cf\r",  # lower-case hex
        b"OKAY26CF",  # no CR
        b"AT\r",
        b"\r",
        b"OK\xffY26CF\r",
        b"OKAY 26C\r",
    ],
)
def test_damaged_reply_is_protocol_error_naming_bytes(raw: bytes) -> None:
    with pytest.raises(ProtocolError) as info:
        parse_reply(raw)
    assert repr(raw)[2:-1][:6] in str(info.value)


def test_unknown_crc_valid_reply_is_protocol_error() -> None:
    raw = line("HELLO WORLD")
    with pytest.raises(ProtocolError, match="unexpected reply") as info:
        parse_reply(raw, data_prefix="TIME")
    assert "HELLO WORLD" in str(info.value)
    # a data reply without a data prefix expected is unknown too
    with pytest.raises(ProtocolError):
        parse_reply(b"TIME 0001E240 0001E2A4E2F2\r")


def test_malformed_error_code_is_protocol_error() -> None:
    with pytest.raises(ProtocolError, match="malformed ERROR"):
        parse_reply(line("ERRORX1"))


def test_find_reply_behind_garbage() -> None:
    assert find_reply(b"AT" + line("OKAY")) == line("OKAY")
    assert find_reply(b"\x00\xff" + line("SPX 1.0 S 4 128")) == line("SPX 1.0 S 4 128")
    assert find_reply(b"AT\r") is None
    assert find_reply(b"") is None


def test_conf_reply_golden_vector() -> None:
    """docs/protocols/mcs1.md §6: the reply to ``CONF:`` and its fields."""
    golden = bytes.fromhex(
        "43 4F 4E 46 20 52 41 54 45 3D 32 30 30 30 30 30 20 43 41 4D 53 3D 32 38 31 32 36 0D"
    )
    reply = parse_reply(golden, data_prefix="CONF")
    assert reply.kind == "data" and reply.text == "CONF RATE=200000 CAMS=2"
    assert parse_conf(reply.text) == {"RATE": "200000", "CAMS": "2"}
