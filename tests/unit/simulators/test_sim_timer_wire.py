"""The device side of the TMR bytes against the golden vectors of docs/protocols/timer.md §6."""

from __future__ import annotations

import pytest

from spotlab.simulators import timer_wire as tw
from spotlab.simulators import wire

GOLDEN_FRAME = bytes.fromhex(
    "A55A0410070044006E74"
    "D2040000CB04FB7120000200"
    "EE2FCE733A0B0000"
    "050000000301190638071600"
    "B5FFCD733A0B000000012900"
    "1E28CE733A0B000081010200"
    "000000000000000000000000"
    "3FD2"
)
TICK = 12_345_678_901_230


def test_data_frame_matches_the_golden_vector() -> None:
    edges = [
        tw.EdgeRecord(TICK - 12_345, 0, True, 41),
        tw.EdgeRecord(TICK - 2_000, tw.CHANNEL_OUTPUT | 1, True, 2),
    ]
    tc = tw.timecode_at(TICK, 25, False)
    payload = tw.tmr_payload(1234, TICK, 0x0020, 0x0005, 0, 3, edges, tc)
    frame = wire.frame(tw.FRAME_TMR, 7, payload, wire.header_flags())
    assert frame == GOLDEN_FRAME
    assert len(frame) == tw.tmr_frame_length(3) == 80


@pytest.mark.parametrize(
    ("text", "golden"),
    [
        ("RATE:250000", b"RATE:250000AD91\r"),
        ("EDGS:8", b"EDGS:8DA45\r"),
        ("ARM:0,1", b"ARM:0,1BB9B\r"),
        ("ARM:3,3", b"ARM:3,3C289\r"),
        ("PULS:1", b"PULS:1A2FD\r"),
        ("POUT:0,1000", b"POUT:0,1000F440\r"),
        ("TCOD:1,30,1", b"TCOD:1,30,13D5C\r"),
        ("TCOD:0", b"TCOD:0208D\r"),
    ],
)
def test_commands_match_the_golden_vectors(text: str, golden: bytes) -> None:
    assert wire.command(text) == golden


def test_replies_match_the_golden_vectors() -> None:
    assert wire.reply("TMR 1.0 SIM00077 8 4 10000000") == b"TMR 1.0 SIM00077 8 4 1000000077B2\r"
    assert wire.reply("PULS 00000B3A73CE2FF2") == b"PULS 00000B3A73CE2FF231C9\r"


def test_drop_frame_labels_skip_two_frames_each_minute_but_the_tenth() -> None:
    minute = tw.timecode_at(600_600_000, 30, True)  # 60.06 s: LTC frame 1800
    assert (minute.hh, minute.mm, minute.ss, minute.ff) == (0, 1, 0, 2)
    before = tw.timecode_at(600_600_000 - 1, 30, True)
    assert (before.mm, before.ss, before.ff) == (0, 59, 29)
    ten = tw.timecode_at(-(-17_982 * 1001 * 10_000_000 // 30_000), 30, True)
    assert (ten.hh, ten.mm, ten.ss, ten.ff) == (0, 10, 0, 0)


def test_non_drop_labels_and_day_wrap() -> None:
    tc = tw.timecode_at(25 * 10_000_000 + 4_000_000, 25, False)  # 25.4 s
    assert (tc.ss, tc.ff) == (25, 10)
    day = 86_400 * 10_000_000
    assert tw.timecode_at(day + 10_000_000, 24, False) == tw.timecode_at(10_000_000, 24, False)
    with pytest.raises(ValueError, match="no LTC rate"):
        tw.timecode_at(0, 29, False)


def test_negative_counter_is_sent_as_twos_complement_and_too_many_edges_refused() -> None:
    payload = tw.tmr_payload(0, -10, 0, 0, 0, 1, [])
    assert payload[12:20] == (2**64 - 10).to_bytes(8, "little")
    with pytest.raises(ValueError, match="do not fit"):
        tw.tmr_payload(0, 0, 0, 0, 0, 1, [tw.EdgeRecord(0, 0, True, 0)] * 2)
