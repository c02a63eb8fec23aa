"""SPX decoding: the golden frame, the corruption matrix, losses, restarts, metadata."""

from __future__ import annotations

from collections.abc import Callable, Iterator

import numpy as np
import pytest
from _spx_wire import (
    GOLDEN_SPX_FRAME,
    GOLDEN_SPX_VALUES,
    Record,
    SpxStream,
    event_frame,
    line,
    mcs1_frame,
)

from spotlab.core.errors import ConfigurationError
from spotlab.core.frames import FrameBlock
from spotlab.drivers.selspot import SelspotConfig, SelspotDecoder, decoder_from_metadata
from spotlab.drivers.selspot.protocol import parse_version

N_FRAMES = 20
J = 10  # the frame the corruption hits


def test_golden_frame_decodes_to_the_spec_table() -> None:
    dec = SelspotDecoder(cameras=2, leds=3, slot_us=100)
    block = dec.feed(GOLDEN_SPX_FRAME, 42)
    assert len(block) == 1
    assert block.seq.tolist() == [65534]
    assert block.ticks.tolist() == [0xFFFFFF00]
    assert block.status.tolist() == [0x0002]
    assert block.arrival_ns.tolist() == [42]
    assert block.data.shape == (1, 3, 2, 3) and block.flags.shape == (1, 3, 2)
    for led, cam, x, y, intensity, flags in GOLDEN_SPX_VALUES:
        got = block.data[0, led, cam]
        if x is None:
            assert np.isnan(got[0]) and np.isnan(got[1])
        else:
            assert got[0] == x and got[1] == y
        assert got[2] == intensity
        assert block.flags[0, led, cam] == flags
    assert dec.stats.frames == 1 and dec.stats.lost_frames == 0 and dec.stats.bytes == 58


def test_golden_version_reply() -> None:
    v = parse_version("SPX 1.0 SIM00042 4 128")
    assert (v.firmware, v.serial_number, v.max_cameras, v.max_leds) == ("1.0", "SIM00042", 4, 128)


def test_valid_flag_clear_gives_nan_even_with_coordinates() -> None:
    s = SpxStream(n_leds=1, n_cams=1, record_fn=lambda i, led, cam: Record(100, 200, 50, 0))
    s.make(1)
    block = SelspotDecoder(1, 1).feed(s.frames[0], 0)
    assert np.isnan(block.data[0, 0, 0, :2]).all() and block.data[0, 0, 0, 2] == 50


def feed(dec: SelspotDecoder, data: bytes, chunking: str) -> FrameBlock:
    blocks = []
    if chunking == "whole":
        blocks.append(dec.feed(data, 1))
    elif chunking == "chunks":
        sizes = [1, 17, 5, 64, 3, 200]
        pos, k = 0, 0
        while pos < len(data):
            n = sizes[k % len(sizes)]
            blocks.append(dec.feed(data[pos : pos + n], k))
            pos, k = pos + n, k + 1
    else:
        blocks.extend(dec.feed(data[i : i + 1], i) for i in range(len(data)))
    blocks.append(dec.flush())
    return FrameBlock.concat(blocks)


def assert_frames(block: FrameBlock, s: SpxStream, indices: list[int], seqs: list[int]) -> None:
    assert block.seq.tolist() == seqs
    assert block.ticks.tolist() == [s.tick0 + i * s.period_us for i in indices]
    expected = np.stack([s.values[i] for i in indices])
    np.testing.assert_array_equal(block.data, expected)  # NaN == NaN here
    np.testing.assert_array_equal(block.flags, np.stack([s.flags[i] for i in indices]))


def flip(frame: bytes, offset: int, bit: int = 0) -> bytes:
    b = bytearray(frame)
    b[offset] ^= 1 << bit
    return bytes(b)


Case = Callable[[SpxStream], bytes]


def _lose_j(f: Callable[[bytes], bytes]) -> Case:
    def build(s: SpxStream) -> bytes:
        return b"".join(f(fr) if i == J else fr for i, fr in enumerate(s.frames))

    return build


# name: (build stream, frames expected lost, crc errors at least, resyncs at least)
LOSS_CASES: dict[str, tuple[Case, int, int]] = {
    "bitflip_sync": (_lose_j(lambda f: flip(f, 1)), 1, 0),
    "bitflip_seq": (_lose_j(lambda f: flip(f, 4, 3)), 1, 1),
    "bitflip_len": (_lose_j(lambda f: flip(f, 6, 2)), 1, 1),
    "bitflip_hcrc": (_lose_j(lambda f: flip(f, 9, 7)), 1, 1),
    "bitflip_prefix": (_lose_j(lambda f: flip(f, 12, 5)), 1, 1),
    "bitflip_record": (_lose_j(lambda f: flip(f, 40, 1)), 1, 1),
    "bitflip_pcrc": (_lose_j(lambda f: flip(f, len(f) - 1, 0)), 1, 1),
    "truncated_in_payload": (_lose_j(lambda f: f[:30]), 1, 1),
    "truncated_in_header": (_lose_j(lambda f: f[:6]), 1, 1),
    "dropped_bytes_payload": (_lose_j(lambda f: f[:20] + f[23:]), 1, 1),
    "dropped_sync_byte": (_lose_j(lambda f: f[1:]), 1, 0),
    "garbage_in_payload": (_lose_j(lambda f: f[:25] + b"AT\r" + f[25:]), 1, 1),
    "burst_three_frames": (
        lambda s: b"".join(
            bytes(len(fr)) if J <= i < J + 3 else fr for i, fr in enumerate(s.frames)
        ),
        3,
        0,
    ),
}


@pytest.fixture(params=["whole", "chunks", "bytes"])
def chunking(request: pytest.FixtureRequest) -> Iterator[str]:
    yield request.param


@pytest.mark.parametrize("case", sorted(LOSS_CASES))
def test_corruption_matrix_losses(case: str, chunking: str) -> None:
    build, lost, min_crc = LOSS_CASES[case]
    s = SpxStream(n_leds=4, n_cams=2).make(N_FRAMES)
    data = build(s)
    dec = SelspotDecoder(2, 4)
    block = feed(dec, data, chunking)
    gone = set(range(J, J + lost))
    kept = [i for i in range(N_FRAMES) if i not in gone]
    assert_frames(block, s, kept, kept)  # no valid frame lost; resync within one frame
    st = dec.stats
    assert st.frames == len(kept)
    assert st.lost_frames == lost and st.gaps == (1 if lost else 0)
    assert st.crc_errors >= min_crc
    assert st.resyncs >= 1, "every corruption shows as skipped bytes"
    assert st.device_dropped == 0 and st.duplicates == 0
    assert st.bytes == len(data)
    assert dec.frame_bytes_accepted + st.bytes_skipped + dec.buffered == len(data)


def test_garbage_between_frames_loses_nothing(chunking: str) -> None:
    s = SpxStream(n_leds=4, n_cams=2).make(N_FRAMES)
    data = b"".join((b"AT\r" + fr) if i == J else fr for i, fr in enumerate(s.frames))
    dec = SelspotDecoder(2, 4)
    block = feed(dec, data, chunking)
    assert_frames(block, s, list(range(N_FRAMES)), list(range(N_FRAMES)))
    assert (dec.stats.resyncs, dec.stats.bytes_skipped, dec.stats.crc_errors) == (1, 3, 0)
    assert dec.stats.lost_frames == 0 and dec.stats.gaps == 0


def test_duplicate_frame_is_dropped_and_counted(chunking: str) -> None:
    s = SpxStream(n_leds=4, n_cams=2).make(N_FRAMES)
    data = b"".join(fr * 2 if i == J else fr for i, fr in enumerate(s.frames))
    dec = SelspotDecoder(2, 4)
    block = feed(dec, data, chunking)
    assert_frames(block, s, list(range(N_FRAMES)), list(range(N_FRAMES)))
    assert dec.stats.duplicates == 1 and dec.stats.lost_frames == 0 and dec.stats.gaps == 0


def test_seq_wrap_at_65535(chunking: str) -> None:
    s = SpxStream(n_leds=4, n_cams=2, seq0=65530, frame_no0=65530).make(N_FRAMES)
    dec = SelspotDecoder(2, 4)
    block = feed(dec, b"".join(s.frames), chunking)
    assert_frames(block, s, list(range(N_FRAMES)), [65530 + i for i in range(N_FRAMES)])
    assert dec.stats.lost_frames == 0 and dec.stats.gaps == 0


def test_seq_wrap_with_a_loss_across_it() -> None:
    s = SpxStream(n_leds=1, n_cams=1, seq0=65533, frame_no0=65533).make(6)
    data = b"".join(fr for i, fr in enumerate(s.frames) if i != 3)  # seq 0 lost
    dec = SelspotDecoder(1, 1)
    block = dec.feed(data, 0)
    assert block.seq.tolist() == [65533, 65534, 65535, 65537, 65538]
    assert dec.stats.lost_frames == 1 and dec.stats.gaps == 1


def test_tick_wrap_at_2_32(chunking: str) -> None:
    s = SpxStream(n_leds=4, n_cams=2, tick0=2**32 - 3 * 5000).make(N_FRAMES)
    dec = SelspotDecoder(2, 4)
    block = feed(dec, b"".join(s.frames), chunking)
    assert block.ticks.tolist() == [2**32 - 15000 + 5000 * i for i in range(N_FRAMES)]
    assert np.all(np.diff(block.ticks) == 5000)


def test_fifo_overflow_counts_device_drops(chunking: str) -> None:
    s = SpxStream(n_leds=4, n_cams=2)
    for i in range(N_FRAMES):
        s.append(i, frame_no=i if i < J else i + 3, status=0x40 if i == J else 0)
    dec = SelspotDecoder(2, 4)
    block = feed(dec, b"".join(s.frames), chunking)
    assert block.seq.tolist() == list(range(N_FRAMES))
    assert block.status[J] == 0x40
    st = dec.stats
    assert (st.lost_frames, st.device_dropped, st.gaps, st.crc_errors) == (3, 3, 1, 0)


def test_link_loss_and_device_drop_in_one_gap() -> None:
    s = SpxStream(n_leds=1, n_cams=1)
    for i in range(6):
        s.append(i, frame_no=i if i < 3 else i + 2)
    data = b"".join(fr for i, fr in enumerate(s.frames) if i != 3)
    dec = SelspotDecoder(1, 1)
    dec.feed(data, 0)
    st = dec.stats
    assert (st.lost_frames, st.device_dropped, st.gaps) == (3, 2, 1)


def test_event_frames_between_data_frames(chunking: str) -> None:
    s = SpxStream(n_leds=4, n_cams=2).make(N_FRAMES)
    data = b"".join(
        (fr + event_frame("WARN83")) if i == J else fr for i, fr in enumerate(s.frames)
    ) + event_frame("OKAY")
    dec = SelspotDecoder(2, 4)
    block = feed(dec, data, chunking)
    assert len(block) == N_FRAMES
    assert [e.payload for e in dec.take_events()] == [line("WARN83"), b"OKAY26CF\r"]
    assert dec.stats.resyncs == 0 and dec.stats.crc_errors == 0


def test_banner_inside_stream_is_reported() -> None:
    s = SpxStream().make(4)
    dec = SelspotDecoder(2, 3)
    dec.feed(s.frames[0] + s.frames[1] + b"RESET7DB2\r", 0)
    assert dec.banner_seen


def test_leading_losses_after_start_are_counted() -> None:
    s = SpxStream(n_leds=1, n_cams=1)
    for i in range(5):
        s.append(i)
    dec = SelspotDecoder(1, 1)
    dec.mark_discontinuity()  # START: acknowledged: the stream counts from 0
    block = dec.feed(b"".join(s.frames[2:]), 0)
    assert block.seq.tolist() == [2, 3, 4]
    assert dec.stats.lost_frames == 2 and dec.stats.gaps == 1


def test_a_new_decoder_joins_a_running_stream_without_counting() -> None:
    s = SpxStream(n_leds=1, n_cams=1, seq0=500, frame_no0=700).make(3)
    dec = SelspotDecoder(1, 1)
    assert dec.feed(b"".join(s.frames), 0).seq.tolist() == [500, 501, 502]
    assert dec.stats.lost_frames == 0 and dec.stats.gaps == 0


def test_mark_discontinuity_starts_a_new_seq_epoch() -> None:
    s = SpxStream(n_leds=1, n_cams=1).make(5)
    dec = SelspotDecoder(1, 1)
    dec.feed(b"".join(s.frames) + s.frames[0][:10], 0)
    dec.mark_discontinuity()
    assert dec.buffered == 0
    block = dec.feed(b"".join(s.frames[:3]), 1)
    assert block.seq.tolist() == [65536, 65537, 65538]
    assert dec.stats.lost_frames == 0 and dec.stats.duplicates == 0
    assert dec.restarts == 0


def test_unannounced_restart_is_detected() -> None:
    s = SpxStream(n_leds=1, n_cams=1).make(5)
    dec = SelspotDecoder(1, 1)
    block = dec.feed(b"".join(s.frames) + b"".join(s.frames[:3]), 0)
    assert block.seq.tolist() == [0, 1, 2, 3, 4, 65536, 65537, 65538]
    assert dec.restarts == 1 and dec.stats.gaps == 1 and dec.stats.lost_frames == 0


def test_frames_contradicting_the_configuration_are_dropped() -> None:
    good = SpxStream(n_leds=2, n_cams=2).make(3)
    other = SpxStream(n_leds=4, n_cams=1)  # same length, other layout
    bad = other.append(1)
    dec = SelspotDecoder(2, 2)
    block = dec.feed(good.frames[0] + bad + good.frames[2], 0)
    assert block.seq.tolist() == [0, 2]
    assert dec.config_mismatches == 1 and dec.stats.lost_frames == 1
    slot = SpxStream(n_leds=2, n_cams=2, slot_us=200).make(1)
    dec2 = SelspotDecoder(2, 2, slot_us=100)
    assert len(dec2.feed(slot.frames[0], 0)) == 0 and dec2.config_mismatches == 1
    assert len(SelspotDecoder(2, 2, slot_us=None).feed(slot.frames[0], 0)) == 1


def test_typical_configuration_4_cameras_32_leds() -> None:
    s = SpxStream(n_leds=32, n_cams=4).make(30)
    assert len(s.frames[0]) == 668
    dec = SelspotDecoder(4, 32)
    block = dec.feed(b"".join(s.frames), 5)
    assert_frames(block, s, list(range(30)), list(range(30)))


def test_decoder_from_metadata_forms() -> None:
    cfg = SelspotConfig.create(cameras=2, leds=[(0, 0x80), (5, 0xC0), (17, 0x40)], rate_hz=200)
    for meta in (
        {"family": "selspot", "config": cfg.to_dict()},
        {"spec": {"metadata": {"config": cfg.to_dict()}}},
        {"metadata": {"config": cfg.to_dict()}},
        cfg.to_dict(),
    ):
        dec = decoder_from_metadata(meta)
        assert (dec.n_cams, dec.n_leds, dec.slot_us) == (2, 3, 100)
        assert len(dec.feed(GOLDEN_SPX_FRAME, 0)) == 1
    with pytest.raises(ConfigurationError, match="no SPX configuration"):
        decoder_from_metadata({"family": "selspot"})
    with pytest.raises(ConfigurationError, match="not a selspot"):
        decoder_from_metadata({"family": "coda", "config": cfg.to_dict()})


def test_decoder_rejects_impossible_layouts() -> None:
    with pytest.raises(ConfigurationError):
        SelspotDecoder(0, 3)
    with pytest.raises(ConfigurationError):
        SelspotDecoder(1, 0)


def test_unknown_frame_type_with_valid_crcs_is_skipped() -> None:
    s = SpxStream().make(2)
    alien = mcs1_frame(0x03, 7, b"\x01\x02\x03")
    dec = SelspotDecoder(2, 3)
    assert len(dec.feed(s.frames[0] + alien + s.frames[1], 0)) == 2
    assert dec.stats.crc_errors == 1 and dec.stats.lost_frames == 0


def test_feed_many_equals_feeding_one_read_at_a_time() -> None:
    s = SpxStream(n_leds=4, n_cams=2).make(40)
    data = b"".join(s.frames)
    chunks = [(data[i : i + 97], 1000 + i) for i in range(0, len(data), 97)]
    one = SelspotDecoder(2, 4)
    expected = FrameBlock.concat([one.feed(d, t) for d, t in chunks])
    many = SelspotDecoder(2, 4)
    got = many.feed_many(chunks)
    np.testing.assert_array_equal(got.arrival_ns, expected.arrival_ns)
    np.testing.assert_array_equal(got.data, expected.data)
    assert got.seq.tolist() == expected.seq.tolist() == list(range(40))
    assert many.stats == one.stats
