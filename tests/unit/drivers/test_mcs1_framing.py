"""MCS-1 frame decoder: golden frames, resynchronisation rules, arrival stamps, banner."""

from __future__ import annotations

import binascii
import random

import numpy as np
import pytest
from _spx_wire import GOLDEN_EVENT_OKAY, GOLDEN_SPX_FRAME, SpxStream, event_frame, mcs1_frame

from spotlab.core.errors import ConfigurationError
from spotlab.drivers.mcs1.framing import FrameDecoder, _header_crc_tables


def accounted(dec: FrameDecoder, fed: int) -> bool:
    return dec.frame_bytes_accepted + dec.stats.bytes_skipped + dec.buffered == fed


def test_golden_data_frame_is_cut_out() -> None:
    dec = FrameDecoder(0x01, 46)
    batch = dec.feed(GOLDEN_SPX_FRAME, 7)
    assert len(batch) == 1
    assert batch.frames[0].tobytes() == GOLDEN_SPX_FRAME
    assert batch.arrival_ns.tolist() == [7]
    assert dec.stats.crc_errors == dec.stats.resyncs == dec.stats.bytes_skipped == 0


def test_golden_event_frame_is_an_event() -> None:
    dec = FrameDecoder(0x01, 46)
    batch = dec.feed(GOLDEN_EVENT_OKAY, 3)
    assert len(batch) == 0
    events = dec.take_events()
    assert [(e.payload, e.arrival_ns) for e in events] == [(b"OKAY26CF\r", 3)]
    assert dec.take_events() == []
    assert event_frame("OKAY") == GOLDEN_EVENT_OKAY


def test_invalid_parameters() -> None:
    with pytest.raises(ConfigurationError):
        FrameDecoder(0x7F, 10)
    with pytest.raises(ConfigurationError):
        FrameDecoder(0x01, 0)
    with pytest.raises(ConfigurationError):
        FrameDecoder(0x01, 4097)


def test_header_crc_tables_match_crc_hqx() -> None:
    rng = random.Random(1)
    c0, tables = _header_crc_tables(0x01, 656)
    for _ in range(500):
        b3, b4, b5 = rng.randrange(256), rng.randrange(256), rng.randrange(256)
        header = bytes([0xA5, 0x5A, 0x01, b3, b4, b5]) + (656).to_bytes(2, "little")
        assert (
            binascii.crc_hqx(header, 0xFFFF) == c0 ^ tables[0][b3] ^ tables[1][b4] ^ tables[2][b5]
        )


def test_long_train_and_single_frames_agree() -> None:
    s = SpxStream(n_leds=4, n_cams=2).make(50)
    data = b"".join(s.frames)
    whole = FrameDecoder(0x01, s.frame_len - 12).feed(data, 1)
    single = FrameDecoder(0x01, s.frame_len - 12)
    parts = [single.feed(f, 1) for f in s.frames]
    assert len(whole) == 50
    assert np.array_equal(whole.frames, np.concatenate([p.frames for p in parts]))


def test_arrival_stamp_is_that_of_the_last_byte() -> None:
    s = SpxStream().make(3)
    dec = FrameDecoder(0x01, s.frame_len - 12)
    a, b, c = s.frames
    assert len(dec.feed(a[:10], 100)) == 0
    batch = dec.feed(a[10:] + b + c[:5], 200)
    assert batch.arrival_ns.tolist() == [200, 200]
    assert dec.feed(c[5:], 300).arrival_ns.tolist() == [300]


def test_frame_found_behind_a_truncated_one_keeps_its_own_stamp() -> None:
    s = SpxStream().make(5)
    dec = FrameDecoder(0x01, s.frame_len - 12)
    # an event frame cut after its header claims 200 bytes: the frames behind it wait
    truncated_event = event_frame("X" * 195)[:12]
    assert len(dec.feed(truncated_event + s.frames[0], 10)) == 0
    batch = dec.feed(b"".join(s.frames[1:5]), 20)
    assert batch.arrival_ns.tolist() == [10, 20, 20, 20, 20]
    assert dec.stats.crc_errors == 1


def test_resync_counts_one_per_skipped_run() -> None:
    s = SpxStream().make(3)
    dec = FrameDecoder(0x01, s.frame_len - 12)
    data = b"AT\r" + s.frames[0] + b"garbage" + s.frames[1] + s.frames[2]
    assert len(dec.feed(data, 1)) == 3
    assert (dec.stats.resyncs, dec.stats.bytes_skipped, dec.stats.crc_errors) == (2, 10, 0)
    assert accounted(dec, len(data))


def test_header_crc_failure_drops_one_byte() -> None:
    s = SpxStream().make(2)
    bad = bytearray(s.frames[0])
    bad[8] ^= 0x01
    dec = FrameDecoder(0x01, s.frame_len - 12)
    assert len(dec.feed(bytes(bad) + s.frames[1], 1)) == 1
    assert dec.stats.crc_errors == 1
    assert dec.stats.resyncs == 1
    assert dec.stats.bytes_skipped == len(bad)


def test_wrong_type_or_length_is_a_header_error() -> None:
    s = SpxStream().make(1)
    other = mcs1_frame(0x02, 0, b"\x00" * (s.frame_len - 12))
    longer = mcs1_frame(0x01, 0, b"\x00" * (s.frame_len - 11))
    v2 = bytearray(mcs1_frame(0x01, 0, b"\x00" * (s.frame_len - 12)))
    v2[3] = 0x20
    v2[8:10] = binascii.crc_hqx(bytes(v2[:8]), 0xFFFF).to_bytes(2, "little")
    dec = FrameDecoder(0x01, s.frame_len - 12)
    data = other + longer + bytes(v2) + s.frames[0]
    assert len(dec.feed(data, 1)) == 1
    assert dec.stats.crc_errors == 3
    assert accounted(dec, len(data))


def test_banner_between_frames_is_seen_even_split() -> None:
    s = SpxStream().make(2)
    dec = FrameDecoder(0x01, s.frame_len - 12)
    dec.feed(s.frames[0] + b"RESE", 1)
    assert not dec.banner_seen
    dec.feed(b"T7DB2\r", 2)
    assert dec.banner_seen
    dec.banner_seen = False
    dec.feed(s.frames[1], 3)
    assert not dec.banner_seen


def test_flush_resolves_a_pending_frame() -> None:
    s = SpxStream().make(2)
    dec = FrameDecoder(0x01, s.frame_len - 12)
    data = s.frames[0][:30] + event_frame("OKAY")  # 51 bytes: less than the claimed 58
    assert len(dec.feed(data, 1)) == 0
    assert dec.take_events() == []  # hidden behind the truncated frame's claimed length
    dec.flush()
    assert [e.payload for e in dec.take_events()] == [b"OKAY26CF\r"]
    assert dec.stats.crc_errors == 1
    assert dec.buffered == 0
    assert accounted(dec, len(data))


def test_flush_of_a_partial_header_only_skips() -> None:
    dec = FrameDecoder(0x01, 46)
    dec.feed(b"\xa5\x5a\x01\x10", 1)
    dec.flush()
    assert (dec.stats.crc_errors, dec.stats.bytes_skipped, dec.buffered) == (0, 4, 0)


def test_sync_byte_at_the_end_is_kept() -> None:
    dec = FrameDecoder(0x01, 46)
    dec.feed(b"xx\xa5", 1)
    assert dec.buffered == 1
    assert len(dec.feed(GOLDEN_SPX_FRAME[1:], 2)) == 1


def test_discard_counts_the_bytes() -> None:
    dec = FrameDecoder(0x01, 46)
    dec.feed(GOLDEN_SPX_FRAME[:30], 1)
    dec.discard()
    assert dec.buffered == 0 and dec.stats.bytes_skipped == 30
    assert len(dec.feed(GOLDEN_SPX_FRAME, 2)) == 1


def test_byte_at_a_time_is_not_quadratic_in_work() -> None:
    s = SpxStream(n_leds=32, n_cams=4).make(3)
    dec = FrameDecoder(0x01, s.frame_len - 12)
    n = 0
    for i, byte in enumerate(b"".join(s.frames)):
        n += len(dec.feed(bytes([byte]), i))
    assert n == 3
