"""Host side of the TMR bytes against the golden vectors of docs/protocols/timer.md §6."""

from __future__ import annotations

import numpy as np
import pytest

from spotlab.core.errors import BandwidthError, ConfigurationError, ProtocolError
from spotlab.drivers.mcs1.commands import encode_command
from spotlab.drivers.timer import TimerConfig, TimerDecoder, decoder_from_metadata, extract_edges
from spotlab.drivers.timer.protocol import parse_version
from spotlab.simulators import timer_wire as tw
from spotlab.simulators import wire

GOLDEN_FRAME = bytes.fromhex(
    "A5 5A 04 10 07 00 44 00 6E 74"
    "D2 04 00 00 CB 04 FB 71 20 00 02 00"
    "EE 2F CE 73 3A 0B 00 00"
    "05 00 00 00 03 01 19 06 38 07 16 00"
    "B5 FF CD 73 3A 0B 00 00 00 01 29 00"
    "1E 28 CE 73 3A 0B 00 00 81 01 02 00"
    "00 00 00 00 00 00 00 00 00 00 00 00"
    "3F D2"
)
COUNTER = 12_345_678_901_230


def test_golden_frame_decodes_to_the_documented_values() -> None:
    decoder = TimerDecoder(3)
    block = decoder.feed(GOLDEN_FRAME, 1000)
    assert block.seq.tolist() == [7]
    assert block.ticks.tolist() == [COUNTER]
    assert block.status.tolist() == [0x20]
    assert block.data.shape == (1, 4, 1, 4)
    rows = block.data[0, :, 0]
    assert rows[0].tolist() == [0, 41, -12_345, 1]
    assert rows[1].tolist() == [129, 2, -2_000, 1]
    assert np.isnan(rows[2]).all()
    assert rows[3].tolist() == [6 * 3600 + 56 * 60 + 7, 22, 25, 0]
    assert decoder.armed == 0x0005 and decoder.edges_lost == 0
    edges = extract_edges([block])
    assert edges.input.tolist() == [0, 129]
    assert edges.tick.tolist() == [12_345_678_888_885, 12_345_678_899_230]
    assert edges.edge_index.tolist() == [41, 2]


@pytest.mark.parametrize(
    ("verb", "args", "golden"),
    [
        ("RATE", "250000", b"RATE:250000AD91\r"),
        ("EDGS", "8", b"EDGS:8DA45\r"),
        ("ARM", "0,1", b"ARM:0,1BB9B\r"),
        ("PULS", "1", b"PULS:1A2FD\r"),
        ("POUT", "0,1000", b"POUT:0,1000F440\r"),
        ("TCOD", "1,30,1", b"TCOD:1,30,13D5C\r"),
        ("TCOD", "0", b"TCOD:0208D\r"),
    ],
)
def test_commands_encode_to_the_golden_vectors(verb: str, args: str, golden: bytes) -> None:
    assert encode_command(verb, args) == golden


def test_version_reply_parses_and_rejects_other_families() -> None:
    v = parse_version("TMR 1.0 SIM00077 8 4 10000000")
    assert (v.inputs, v.outputs, v.tick_hz, v.serial_number) == (8, 4, 10_000_000, "SIM00077")
    with pytest.raises(ProtocolError, match="TMR <firmware>"):
        parse_version("SPX 1.0 SIM00042 4 128")


def test_config_commands_checks_and_round_trip() -> None:
    cfg = TimerConfig.create(rate_hz=250, slots=4, inputs={0: "rising", 3: "both"})
    assert cfg.commands()[:3] == [("RATE", "250000"), ("EDGS", "4"), ("TCOD", "0")]
    assert ("ARM", "3,3") in cfg.commands() and ("ARM", "1,0") in cfg.commands()
    assert TimerConfig.from_dict(cfg.to_dict()) == cfg
    assert TimerConfig.create(timecode=(30, True)).commands()[2] == ("TCOD", "1,30,1")
    with pytest.raises(ConfigurationError, match="edge slots"):
        TimerConfig.create(slots=65)
    with pytest.raises(ConfigurationError, match="inputs are"):
        TimerConfig.create(inputs={8: "rising"})
    with pytest.raises(ConfigurationError, match="timecode"):
        TimerConfig.create(timecode=(29, False))
    with pytest.raises(BandwidthError, match="921600"):
        TimerConfig.create(rate_hz=100, baud=115_200)
    assert TimerConfig.create(rate_hz=100, baud="auto").baud == 921_600


def _frames(
    n: int, slots: int, rng: np.random.Generator
) -> tuple[bytes, list[list[tw.EdgeRecord]]]:
    out, sent = [], []
    counts = [0] * 8
    for k in range(n):
        tick = 10 * (5_000_000 + 10_000 * k)
        edges = []
        for _ in range(int(rng.integers(0, slots + 1))):
            ch = int(rng.integers(0, 8))
            edges.append(tw.EdgeRecord(tick - int(rng.integers(0, 100_000)), ch, True, counts[ch]))
            counts[ch] += 1
        sent.append(edges)
        payload = tw.tmr_payload(k, tick, 0, 0xFFFF, 0, slots, edges)
        out.append(wire.frame(tw.FRAME_TMR, k, payload, wire.header_flags()))
    return b"".join(out), sent


def test_round_trip_through_split_reads_keeps_every_edge_and_unwraps_counts() -> None:
    rng = np.random.default_rng(5)
    data, sent = _frames(300, 6, rng)
    decoder = decoder_from_metadata(
        {"family": "timer", "config": {"slots": 6, "rate_mhz": 100_000}}
    )
    blocks = []
    for i in range(0, len(data), 37):
        blocks.append(decoder.feed(data[i : i + 37], i))
    edges = extract_edges(blocks)
    flat = [e for frame in sent for e in frame]
    assert edges.tick.tolist() == [e.tick for e in flat]
    assert edges.input.tolist() == [e.channel for e in flat]
    assert edges.edge_index.tolist() == [e.count for e in flat]
    assert edges.frame_ticks.shape == (300,) and decoder.stats.frames == 300


def test_edge_counts_unwrap_past_16_bits() -> None:
    frames = []
    for k, count in enumerate((65_534, 65_535, 0, 1)):
        payload = tw.tmr_payload(k, 10 * k, 0, 1, 0, 1, [tw.EdgeRecord(10 * k, 2, True, count)])
        frames.append(wire.frame(tw.FRAME_TMR, k, payload, wire.header_flags()))
    edges = extract_edges([TimerDecoder(1).feed(b"".join(frames), 0)])
    assert edges.edge_index.tolist() == [65_534, 65_535, 65_536, 65_537]


def test_frames_of_another_slot_count_are_dropped_and_counted() -> None:
    payload = tw.tmr_payload(0, 0, 0, 0, 0, 2, [])
    frame = wire.frame(tw.FRAME_TMR, 0, payload, wire.header_flags())
    decoder = TimerDecoder(2)
    bad = bytearray(payload)
    bad[24] = 3  # n_slots says 3 while the frame holds 2
    assert len(decoder.feed(frame, 0)) == 1
    wrong = wire.frame(tw.FRAME_TMR, 1, bytes(bad), wire.header_flags())
    assert len(decoder.feed(wrong, 0)) == 0 and decoder.config_mismatches == 1


def test_extract_edges_refuses_other_blocks_and_metadata_of_other_families() -> None:
    from spotlab.core.frames import FrameBlock

    with pytest.raises(ConfigurationError, match="not a timer frame block"):
        extract_edges([FrameBlock.empty(8, 2, 3)])
    with pytest.raises(ConfigurationError, match="not a timer one"):
        decoder_from_metadata({"family": "selspot"})
    assert len(extract_edges([])) == 0
