"""The host side of the CEN bytes: golden vectors of docs/protocols/centroid.md §5, split
reads, damage, losses, malformed frames, and the ragged blob table."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from spotlab.core.errors import BandwidthError, ConfigurationError
from spotlab.drivers.centroid import (
    BLOB_EDGE,
    BLOB_MERGED,
    BLOB_SATURATED,
    CAM_OFFLINE,
    CAM_OVERFLOW,
    CentroidConfig,
    CentroidDecoder,
    blobs_from_blocks,
    decoder_from_metadata,
)
from spotlab.drivers.centroid.protocol import parse_version
from spotlab.drivers.mcs1.commands import encode_command
from spotlab.testing.golden import golden_vector

SPEC = Path(__file__).parents[3] / "docs" / "protocols" / "centroid.md"
GOLDEN_FRAME = golden_vector(SPEC, "Data frame")
GOLDEN_OVERFLOW = golden_vector(SPEC, "Overflowing camera")
GOLDEN_CONFIG = CentroidConfig(camera_mask=5, max_blobs=4)


def test_golden_frame_decodes_to_the_documented_values() -> None:
    dec = CentroidDecoder(GOLDEN_CONFIG)
    block = dec.feed(GOLDEN_FRAME, 99)
    assert len(block) == 1 and block.data.shape == (1, 4, 3, 4)
    assert int(block.ticks[0]) == 0x71FB04CB and int(block.status[0]) == 0x20
    blobs = blobs_from_blocks([block])
    np.testing.assert_array_equal(blobs.counts, [[3, 0, 0]])
    np.testing.assert_allclose(blobs.uv, [[640.5, 512.25], [12.03125, 1000.0], [100.0, 200.0]])
    np.testing.assert_array_equal(blobs.area, [38, 9, 70])
    np.testing.assert_array_equal(blobs.peak, [201, 255, 180])
    np.testing.assert_array_equal(blobs.flags, [0, BLOB_SATURATED | BLOB_EDGE, BLOB_MERGED])
    assert blobs.exposure_us[0, 0] == 12_345_678_901
    assert np.isnan(blobs.exposure_us[0, 2]) and np.isnan(blobs.exposure_us[0, 1])
    assert blobs.offline[0].tolist() == [False, False, True]
    np.testing.assert_array_equal(blobs.camera_frame, [[1234, -1, 1200]])
    assert dec.camera_gaps.tolist() == [0, 0, 1]


def test_overflow_golden_frame_is_flagged() -> None:
    dec = CentroidDecoder(CentroidConfig(camera_mask=1, max_blobs=1))
    blobs = blobs_from_blocks([dec.feed(GOLDEN_OVERFLOW, 0)])
    assert blobs.overflow[0, 0] and int(blobs.n_found[0, 0]) == 7
    np.testing.assert_allclose(blobs.uv, [[1.0, 2.0]])
    assert dec.summary()["overflow_frames"] == [1]
    assert CAM_OVERFLOW == 1 and CAM_OFFLINE == 2


def test_commands_encode_as_the_golden_vectors() -> None:
    assert encode_command("CAMS", "255") == b"CAMS:255C6B4\r"
    assert encode_command("BLOB", "256") == b"BLOB:2567E45\r"
    assert encode_command("COMM", "11") == b"COMM:112E09\r"
    assert encode_command("COMM", "12") == b"COMM:121E6A\r"
    v = parse_version("CEN 1.0 SIM00091 8 1024 1000000")
    assert (v.cameras, v.max_blobs, v.tick_hz) == (8, 1024, 1_000_000)


def test_split_reads_give_the_same_frames() -> None:
    stream = GOLDEN_FRAME * 3
    whole = CentroidDecoder(GOLDEN_CONFIG).feed(stream, 0)
    dec = CentroidDecoder(GOLDEN_CONFIG)
    parts = [dec.feed(stream[i : i + 7], i) for i in range(0, len(stream), 7)]
    joined = blobs_from_blocks(parts)
    assert joined.n_frames == 1  # the same seq 7 three times: duplicates dropped
    assert len(whole) == 1
    assert dec.stats.duplicates == 2


def test_damaged_frame_is_counted_and_the_next_one_found() -> None:
    bad = bytearray(GOLDEN_FRAME)
    bad[40] ^= 0x10
    good = bytearray(GOLDEN_FRAME)
    good[4] = 8  # seq 8, header CRC recomputed below
    import binascii

    good[8:10] = binascii.crc_hqx(bytes(good[:8]), 0xFFFF).to_bytes(2, "little")
    dec = CentroidDecoder(GOLDEN_CONFIG)
    block = dec.feed(bytes(bad) + bytes(good), 0)
    assert len(block) == 1 and dec.stats.crc_errors >= 1


def test_frame_of_another_configuration_is_dropped_as_malformed() -> None:
    dec = CentroidDecoder(CentroidConfig(camera_mask=5, max_blobs=8))
    assert len(dec.feed(GOLDEN_FRAME, 0)) == 0
    assert dec.malformed == 1


def test_blocks_of_different_blob_widths_join() -> None:
    dec = CentroidDecoder(CentroidConfig(camera_mask=1, max_blobs=1))
    a = dec.feed(GOLDEN_OVERFLOW, 0)
    dec2 = CentroidDecoder(GOLDEN_CONFIG)
    with pytest.raises(ConfigurationError, match="one blobs2d stream"):
        blobs_from_blocks([a, dec2.feed(GOLDEN_FRAME, 0)])


def test_configuration_errors_name_the_cause() -> None:
    with pytest.raises(ConfigurationError, match="exposure"):
        CentroidConfig(rate_mhz=1_000_000, exposure_us=2000)
    with pytest.raises(BandwidthError, match="65535"):
        CentroidConfig.create(cameras=16, max_blobs=1024)
    with pytest.raises(BandwidthError, match="faster baud"):
        CentroidConfig.create(cameras=16, rate_hz=2000, exposure_us=100, baud=115_200)


def test_decoder_from_metadata_round_trips_the_configuration() -> None:
    cfg = CentroidConfig.create(cameras=3, rate_hz=300, max_blobs=64)
    dec = decoder_from_metadata({"family": "centroid", "config": cfg.to_dict()})
    assert dec.config == cfg
    with pytest.raises(ConfigurationError, match="not a centroid"):
        decoder_from_metadata({"family": "timer"})
