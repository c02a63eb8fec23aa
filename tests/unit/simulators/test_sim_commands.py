"""The command layer of the simulated SPX device: every reply and every ERRORxx path."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest
from _simwire import MS, Host, S, cmd, decode, reply_text, spx

from spotlab.simulators import wire
from spotlab.simulators.selspot import SelspotDevice

TABLE32 = "".join(f"{i:02X}80" for i in range(32))


def test_power_up_banner_at_9600(make_device: Callable[..., SelspotDevice]) -> None:
    h = Host(make_device())
    # 10 bit times per byte at 9600 baud: byte 5 is complete at 5.2083 ms.
    assert h.wait(5_208_000) == b"RESE"
    assert h.wait(1_000) == b"T"
    assert h.wait(6 * MS) == b"7DB2\r"
    assert h.dev.baud == 9600


def test_version_reply(host: Host) -> None:
    assert host.ask("VER:0") == "SPX 1.0 SIM00042 4 128"


def test_cameras_beyond_the_rig_are_not_connected(
    make_device: Callable[..., SelspotDevice],
) -> None:
    h = Host(make_device(cameras=2))
    h.wait(20 * MS)
    assert h.ask("VER:0") == "SPX 1.0 SIM00042 4 128"  # the product's limits, not the rig's
    h.configure(4, 8, 100_000)
    h.buf.clear()
    h.send(cmd("START:"), baud=2_000_000)
    h.wait(100 * MS)
    frames = [spx(f["payload"]) for f in decode(bytes(h.buf)).frames if f["type"] == 1]
    assert frames and all(f["n_cams"] == 4 for f in frames)
    for f in frames:
        assert np.all(f["x"][:, 2:] == 0xFFF) and np.all(f["intensity"][:, 2:] == 0)  # type: ignore[index]
        assert np.all(f["flags"][:, 2:] == wire.FLAG_LOW_SIGNAL)  # type: ignore[index]
    assert any(np.any(f["flags"][:, :2] & wire.FLAG_VALID) for f in frames)  # type: ignore[index]


def test_space_form_needs_no_crc(host: Host) -> None:
    assert host.ask_raw("", raw=b"VER 0\r").startswith(b"SPX 1.0")
    assert reply_text(host.ask_raw("", raw=b"CAMS 2\r")) == "OKAY"
    assert reply_text(host.ask_raw("", raw=b"\nSTAT\r")) == "STAT 0020"  # CR LF from a terminal


def test_empty_line_is_ignored(host: Host) -> None:
    assert host.ask_raw("", raw=b"\r\r") == b""


@pytest.mark.parametrize("raw", [cmd("BOGUS:1"), b"AT\r", b"ver 0\r", cmd("ver:0")])
def test_unknown_command_is_error_01(host: Host, raw: bytes) -> None:
    assert reply_text(host.ask_raw("", raw=raw)) == "ERROR01"


def test_too_long_is_error_02(host: Host) -> None:
    assert reply_text(host.ask_raw("", 500 * MS, raw=b"X" * 256 + b"\r")) == "ERROR02"
    assert reply_text(host.ask_raw("", 500 * MS, raw=b"X" * 255 + b"\r")) == "ERROR01"
    # An LEDT line may carry a full table of 128 entries (521 bytes); the limit is 1024.
    full = "LEDT:" + "".join(f"{i:02X}80" for i in range(128))
    assert host.ask(full, 700 * MS) == "OKAY"
    assert host.ask("COMM:5") == "OKAY"  # 1 kB take more than the 1 s timeout at 9600 baud
    assert reply_text(host.ask_raw("", 200 * MS, raw=b"LEDT " + b"0" * 1020 + b"\r")) == "ERROR02"
    assert reply_text(host.ask_raw("", 200 * MS, raw=b"LEDT " + b"0" * 1016 + b"\r")) == "ERROR81"


@pytest.mark.parametrize("raw", [b"VER:0\r", b"START:\r", b"COMM:8AB\r"])
def test_crc_form_without_room_for_a_crc_is_error_03(host: Host, raw: bytes) -> None:
    assert reply_text(host.ask_raw("", raw=raw)) == "ERROR03"


def test_bad_crc_is_error_04_and_sets_status_bit(host: Host) -> None:
    assert host.ask("STAT:") == "STAT 0000"
    assert host.ask_raw("", raw=b"VER:00000\r") == wire.reply("ERROR04")
    assert reply_text(host.ask_raw("", raw=b"BOGUS:12G4\r")) == "ERROR04"  # CRC before verb
    assert host.ask("STAT:") == "STAT 0004"
    assert host.ask("STAT:") == "STAT 0000"  # reported once


def test_unfinished_command_times_out_with_error_05(host: Host) -> None:
    host.send(b"VER:0F7")
    assert host.wait(990 * MS) == b""
    assert reply_text(host.wait(50 * MS)) == "ERROR05"
    # The partial line is gone: the next command stands on its own.
    assert host.ask("VER:0").startswith("SPX")


@pytest.mark.parametrize(
    "text",
    [
        "VER:",
        "START:1",
        "AGC:1",
        "AGC:1,2,3",
        "RATE:1000,2000",
        "STAT:1",
        "TIME:0",
        "LEDQ:1",
        "INIT:1",
        "CAMS:",
    ],
)
def test_wrong_parameter_count_is_error_07(host: Host, text: str) -> None:
    assert host.ask(text) == "ERROR07"


@pytest.mark.parametrize(
    "text",
    [
        "CAMS:0", "CAMS:5", "SLOT:49", "SLOT:1001", "RATE:999", "RATE:10000001", "RATE:abc",
        "BGND:3", "AGC:2,160", "AGC:1,0", "AGC:1,256", "COMM:10", "COMM:x", "VER:1", "SLOT:-5",
    ],
)  # fmt: skip
def test_out_of_range_is_error_23(host: Host, text: str) -> None:
    assert host.ask(text) == "ERROR23"


@pytest.mark.parametrize("value", ["0", "100", "1000", "250"])
def test_slot_limits_accepted(host: Host, value: str) -> None:
    assert host.ask(f"SLOT:{value}") == ("OKAY" if value != "0" else "ERROR23")


@pytest.mark.parametrize(
    "table",
    [
        "",  # empty
        "".join(f"{i:02X}80" for i in range(128)) + "0080",  # more than 128 (and an id twice)
        "8080",  # id above 7F
        "00800080",  # id twice
        "008",  # not a multiple of 4
        "00G0",  # not hex
        "0080,0180",  # not one string of entries
    ],
)
def test_bad_led_table_is_error_81(host: Host, table: str) -> None:
    assert host.ask(f"LEDT:{table}", 800 * MS) == "ERROR81"


def test_led_table_limits_and_readback(host: Host) -> None:
    full = "".join(f"{i:02X}{i + 1:02X}" for i in range(128))
    assert host.ask(f"LEDT:{full}", 700 * MS) == "OKAY"
    assert host.ask("LEDT:008005C01140") == "OKAY"
    assert host.ask("LEDQ:") == "LEDQ 008005C01140"
    assert host.ask("LEDT:7fff") == "OKAY"  # lower-case hex accepted, read back upper-case
    assert host.ask("LEDQ:") == "LEDQ 7FFF"


def test_not_configured_is_error_82(host: Host) -> None:
    assert host.ask("START:") == "ERROR82"
    assert host.ask("LEDQ:") == "ERROR82"


def test_timing_is_checked_before_bandwidth(host: Host) -> None:
    table = "".join(f"{i:02X}80" for i in range(128))
    assert host.ask(f"LEDT:{table}", 700 * MS) == "OKAY"
    assert host.ask("RATE:100000") == "OKAY"
    assert host.ask("START:") == "ERROR23"  # (128 + 1) * 100 us > 10 ms
    assert host.ask("RATE:77000") == "OKAY"  # 12.99 ms >= 12.9 ms: timing fine, 9600 baud is not
    assert host.ask("START:") == "ERROR80"
    assert host.ask("BGND:2") == "OKAY"  # one more (dark) slot: 13.0 ms > 12.99 ms
    assert host.ask("START:") == "ERROR23"


def test_bandwidth_example_of_the_spec(host: Host) -> None:
    # 4 cameras x 32 LEDs at 200 Hz need 1.336 Mbit/s: refused at 115200 and at 1 Mbaud.
    for code, verdict in ((5, "ERROR80"), (7, "ERROR80"), (8, "OKAY")):
        assert host.ask(f"COMM:{code}") == "OKAY"
        for text in ("CAMS:4", f"LEDT:{TABLE32}", "RATE:200000"):
            assert host.ask(text, 20 * MS) == "OKAY"
        assert host.ask("START:", 20 * MS) == verdict
    assert host.dev.streaming


def test_bandwidth_boundary_is_inclusive(host: Host) -> None:
    # 1 camera, 2 LEDs: 38-byte frames; 9600 baud * 0.8 / 380 bits = 20.21 Hz.
    assert host.ask("LEDT:00800180") == "OKAY"
    assert host.ask("RATE:20211") == "OKAY"
    assert host.ask("START:") == "ERROR80"
    assert host.ask("RATE:20210") == "OKAY"
    assert host.ask("START:") == "OKAY"


def test_comm_answers_at_the_old_rate_then_switches(host: Host) -> None:
    host.send(cmd("COMM:8"))  # 11 bytes at 9600 = 11.46 ms
    assert host.wait(11 * MS) == b""
    assert host.wait(1 * MS) == b""  # command complete at 11.46 ms, first reply byte at 12.5 ms
    assert host.wait(8 * MS) == b"OKAY26CF"  # 8 bytes by 20.0 ms, the 9th at 20.83 ms
    assert host.dev.baud == 9600
    assert host.wait(1 * MS) == b"\r"
    assert host.dev.baud == 2_000_000
    host.send(cmd("VER:0"), baud=2_000_000)
    assert reply_text(host.wait(1 * MS)) == "SPX 1.0 SIM00042 4 128"


def test_host_at_the_wrong_rate_is_not_understood(host: Host) -> None:
    assert host.ask("COMM:5") == "OKAY"
    host.buf.clear()
    host.send(cmd("VER:0"), baud=9600)  # the device listens at 115200 now
    host.wait(1200 * MS)
    assert b"SPX" not in host.buf
    host.send(cmd("STAT:"), baud=115_200)
    assert host.wait(5 * MS).endswith(wire.reply("STAT 0001"))  # comm sync error seen


def test_reset_command_and_break_restore_defaults(host: Host) -> None:
    assert host.ask("COMM:6") == "OKAY"
    assert host.ask("LEDT:0080") == "OKAY"
    assert host.ask_raw("RESET:", 30 * MS) == wire.BANNER
    assert host.dev.baud == 9600
    assert host.ask("LEDQ:") == "ERROR82"
    assert host.ask("COMM:6") == "OKAY"
    host.dev.send_break(host.t)
    assert host.wait(30 * MS) == wire.BANNER
    assert host.dev.baud == 9600


def test_init_restores_defaults_but_keeps_the_rate(host: Host) -> None:
    assert host.ask("COMM:5") == "OKAY"
    assert host.ask("LEDT:0080") == "OKAY"
    assert host.ask("INIT:") == "OKAY"
    assert host.dev.baud == 115_200
    assert host.ask("LEDQ:") == "ERROR82"


def test_time_probe_ticks(host: Host) -> None:
    raw = cmd("TIME:")  # 10 bytes at 9600: the last arrives 10.42 ms after the write
    host.send(raw)
    t_write = host.t
    host.wait(60 * MS)
    text = reply_text(bytes(host.buf))
    _, rx, tx = text.split()
    rx_us, tx_us = int(rx, 16), int(tx, 16)
    expected_rx = (t_write - host.dev.clock.epoch_ns + len(raw) * 10**10 // 9600) // 1000
    assert rx_us == expected_rx
    assert tx_us == rx_us  # idle line: the reply starts as soon as the command is in


def test_time_tx_tick_waits_for_a_busy_line(host: Host) -> None:
    host.send(cmd("VER:0") + cmd("TIME:"))  # VER's 27-byte reply keeps the line busy
    host.wait(100 * MS)
    text = reply_text(bytes(host.buf).split(b"\r", 1)[1])
    _, rx, tx = text.split()
    busy_us = int(tx, 16) - int(rx, 16)
    # TIME's 10 bytes end 10.42 ms after VER's; VER's 27-byte reply takes 28.125 ms.
    expected = (27 - 10) * 10**7 // 9600
    assert abs(busy_us - expected) <= 1


def test_configuration_while_streaming_is_refused_in_event_frames(host: Host) -> None:
    host.configure(1, 4, 50_000)
    host.buf.clear()
    host.send(cmd("START:"), baud=2_000_000)
    host.wait(1 * MS)
    assert bytes(host.buf).startswith(wire.reply("OKAY") + b"\xa5\x5a\x01")  # START's reply is bare
    refused = ("CAMS:1", f"LEDT:{TABLE32}", "SLOT:100", "RATE:50000", "BGND:1", "AGC:0,160")
    for text in (*refused, "INIT:", "COMM:5", "START:"):
        host.buf.clear()
        host.send(cmd(text), baud=2_000_000)
        host.wait(2 * MS)
        events = [f for f in decode(bytes(host.buf)).frames if f["type"] == 0x7F]
        assert [reply_text(f["payload"]) for f in events] == ["ERROR0C"], text  # type: ignore[arg-type]
        assert events[0]["seq"] == 0 and events[0]["flags"] == 0x14
    host.buf.clear()
    host.send(cmd("LEDQ:") + cmd("STAT:") + cmd("VER:0"), baud=2_000_000)
    host.wait(5 * MS)
    texts = [reply_text(f["payload"]) for f in decode(bytes(host.buf)).frames if f["type"] == 0x7F]  # type: ignore[arg-type]
    # STAT reports "configuration changed" once: the set-up before START.
    assert texts == ["LEDQ 0080018002800380", "STAT 0020", "SPX 1.0 SIM00042 4 128"]


def test_stop_reply_is_an_event_frame_and_ends_the_data(host: Host) -> None:
    host.configure(2, 8, 200_000)
    host.send(cmd("START:"), baud=2_000_000)
    host.wait(200 * MS)
    host.buf.clear()
    host.send(cmd("STOP:"), baud=2_000_000)
    host.wait(50 * MS)
    host.wait(1 * S)
    frames = decode(bytes(host.buf)).frames
    kinds = [f["type"] for f in frames]
    assert kinds[-1] == 0x7F
    assert reply_text(frames[-1]["payload"]) == "OKAY"  # type: ignore[arg-type]
    assert not host.dev.streaming
    assert decode(bytes(host.buf)).rest == b""
    assert host.ask("STOP:") == "OKAY"  # stopping again: a bare OKAY


def test_frames_follow_start_and_agc_currents_read_back(host: Host) -> None:
    host.configure(4, 32, 200_000, extra=("AGC:1,160",))
    host.send(cmd("START:"), baud=2_000_000)
    host.wait(500 * MS)
    host.send(cmd("STOP:"), baud=2_000_000)
    host.wait(20 * MS)
    frames = [f for f in decode(bytes(host.buf)).frames if f["type"] == 1]
    assert len(frames) >= 95
    assert spx(frames[0]["payload"])["status"] & wire.STATUS_CONFIG_CHANGED  # type: ignore[arg-type,operator]
    assert not spx(frames[1]["payload"])["status"] & wire.STATUS_CONFIG_CHANGED  # type: ignore[arg-type,operator]
    currents = host.ask("LEDQ:").split()[1]
    assert len(currents) == 4 * 32 and currents != TABLE32  # AGC moved some currents


@pytest.mark.parametrize("verb", ["STAT:", "TIME:", "VER:0"])
def test_space_and_crc_forms_agree(host: Host, verb: str) -> None:
    a = host.ask(verb)
    b = reply_text(host.ask_raw("", raw=verb.replace(":", " ").encode() + b"\r"))
    assert a.split()[0] == b.split()[0]


def test_device_emits_the_golden_replies_and_event_frame(
    make_device: Callable[..., SelspotDevice],
) -> None:
    h = Host(make_device(mark_simulated=False))
    assert h.wait(20 * MS) == bytes.fromhex("52 45 53 45 54 37 44 42 32 0D")  # banner
    assert h.ask_raw("VER:0") == b"SPX 1.0 SIM00042 4 128C2DE\r"
    assert h.ask_raw("START:") == bytes.fromhex("45 52 52 4F 52 38 32") + wire.reply("ERROR82")[7:]
    assert h.ask_raw("COMM:8") == bytes.fromhex("4F 4B 41 59 32 36 43 46 0D")
    h.send(cmd("LEDT:008005C01140"), baud=2_000_000)
    h.send(cmd("START:"), baud=2_000_000)
    h.wait(50 * MS)
    h.buf.clear()
    h.send(cmd("STOP:"), baud=2_000_000)
    h.wait(50 * MS)
    golden = bytes.fromhex("A5 5A 7F 10 00 00 09 00 ED D8 4F 4B 41 59 32 36 43 46 0D 5C D3")
    assert bytes(h.buf).endswith(golden)
