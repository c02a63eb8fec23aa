"""The driver's NatNet reader against the golden vectors of docs/protocols/natnet.md §6."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from spotlab.core.errors import ConfigurationError
from spotlab.drivers.natnet import (
    NatNetDecoder,
    NatNetFormatError,
    parse_address,
    parse_frame,
    parse_server_info,
    split_packet,
)
from spotlab.testing.golden import golden_vector

SPEC = Path(__file__).parents[3] / "docs" / "protocols" / "natnet.md"
GOLDEN_SERVER_INFO = golden_vector(SPEC, "Server info")
GOLDEN_FRAME_41 = golden_vector(SPEC, "A frame with 2 labelled markers")
GOLDEN_FRAME_31 = golden_vector(SPEC, "The same frame in NatNet 3.1")
A, B = [0.25, -0.5, 1.125], [-0.75, 1.5, 0.0625]


def test_server_info_golden() -> None:
    message_id, payload = split_packet(GOLDEN_SERVER_INFO)
    info = parse_server_info(payload)
    assert message_id == 1 and info.name == "spotlab-natnet-sim"
    assert info.app_version == (3, 1, 0, 0) and info.version == (4, 1)
    assert (info.clock_hz, info.data_port, info.multicast) == (10_000_000, 1511, False)
    assert info.group == "239.255.42.99"


@pytest.mark.parametrize(
    ("version", "golden"), [((4, 1), GOLDEN_FRAME_41), ((3, 1), GOLDEN_FRAME_31)]
)
def test_frame_golden(version: tuple[int, int], golden: bytes) -> None:
    message_id, payload = split_packet(golden)
    f = parse_frame(payload, version)
    assert message_id == 7 and f.frame_number == 1234
    np.testing.assert_array_equal(f.marker_sets["walker"], [A, B])
    assert f.labelled_ids == (0x00010001, 0x00010002) and f.labelled_params == (0x0C, 0x0C)
    np.testing.assert_array_equal(f.labelled_m, [A, B])
    assert (f.timecode, f.timecode_sub, f.timestamp_s) == (0x01020304, 0, 10.25)
    assert f.stamps == (102_500_000, 102_520_000, 102_530_000) and f.params == 0
    assert f.rigid_bodies == {}


def test_decoder_cuts_packets_from_any_split_and_counts_gaps() -> None:
    dec = NatNetDecoder((4, 1), "walker", ["A", "B"])
    stream = GOLDEN_SERVER_INFO + GOLDEN_FRAME_41
    second = bytearray(GOLDEN_FRAME_41)
    second[4:8] = (1237).to_bytes(4, "little")
    stream += bytes(second) + GOLDEN_FRAME_41  # 1234 again: a duplicate
    blocks = [dec.feed(stream[i : i + 7], 100 + i) for i in range(0, len(stream), 7)]
    seq = np.concatenate([b.seq for b in blocks])
    assert list(seq) == [1234, 1237]
    data = np.concatenate([b.data for b in blocks if len(b)])
    np.testing.assert_array_equal(data[0, :, 0], np.array([A, B]) * 1000.0)
    assert (dec.stats.frames, dec.stats.lost_frames, dec.stats.gaps) == (2, 2, 1)
    assert dec.stats.duplicates == 1


def test_malformed_frames_are_counted_not_raised() -> None:
    dec = NatNetDecoder((4, 1), "walker", ["A", "B"])
    bad = bytearray(GOLDEN_FRAME_41[:-30])
    bad[2:4] = len(bad[4:]).to_bytes(2, "little")
    assert len(dec.feed(bytes(bad) + GOLDEN_FRAME_41, 0)) == 1
    assert dec.stats.crc_errors == 1
    with pytest.raises(NatNetFormatError):
        split_packet(b"\x07\x00\xff\x00abc")
    with pytest.raises(NatNetFormatError, match="unknown NatNet message"):
        split_packet(b"\x55\x55\x00\x00")


def test_address() -> None:
    assert parse_address("127.0.0.1") == ("127.0.0.1", 1510)
    assert parse_address("mocap.lab:1610") == ("mocap.lab", 1610)
    with pytest.raises(ConfigurationError):
        parse_address("127.0.0.1:0")


@pytest.mark.parametrize("version", [(3, 1), (4, 1)])
def test_damaged_packets_raise_only_the_documented_error(version: tuple[int, int]) -> None:
    rng = np.random.default_rng(5)
    golden = GOLDEN_FRAME_41 if version == (4, 1) else GOLDEN_FRAME_31
    dec = NatNetDecoder(version, "walker", ["A", "B"])
    for _ in range(3000):
        data = bytearray(golden)
        for _ in range(int(rng.integers(1, 6))):
            data[int(rng.integers(0, len(data)))] = int(rng.integers(0, 256))
        if rng.random() < 0.3:
            data = data[: int(rng.integers(0, len(data)))]
        dec.feed(bytes(data), 0)  # never raises: damage is counted
        try:
            parse_frame(bytes(data[4:]), version)
        except NatNetFormatError:
            pass
    assert dec.stats.crc_errors + dec.stats.resyncs > 0
