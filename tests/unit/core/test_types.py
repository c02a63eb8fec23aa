from __future__ import annotations

import numpy as np
import pytest

from spotlab.core import ConfigurationError, FrameBlock, StreamSpec, crc16, crc16_hex, crc32


def _spec(slot: float | None = 100e-6) -> StreamSpec:
    return StreamSpec(
        name="s",
        kind="image2d",
        n_sensors=2,
        n_markers=3,
        rate_hz=200.0,
        tick_hz=1e6,
        slot_period_s=slot,
        values=("x", "y", "intensity"),
        units=("count", "count", "count"),
    )


def test_crc16_is_ccitt_false() -> None:
    assert crc16(b"123456789") == 0x29B1
    assert crc16_hex("RESET") == "7DB2"
    # A running CRC continues where the last left off.
    assert crc16(b"6789", crc16(b"12345")) == 0x29B1
    assert crc32(b"123456789") == 0xCBF43926


def test_slot_offsets_follow_k_plus_half() -> None:
    assert _spec().sample_offsets_ns().tolist() == [50_000, 150_000, 250_000]
    assert _spec(None).sample_offsets_ns().tolist() == [0, 0, 0]


def test_sample_ticks_add_slot_offsets_to_frame_ticks() -> None:
    block = FrameBlock(
        seq=np.array([0, 1]),
        ticks=np.array([1000, 6000]),
        arrival_ns=np.array([5, 6]),
        data=np.zeros((2, 3, 2, 3)),
        flags=np.zeros((2, 3, 2), np.uint8),
        status=np.zeros(2, np.uint16),
    )
    np.testing.assert_allclose(
        block.sample_ticks(_spec()), [[1050, 1150, 1250], [6050, 6150, 6250]]
    )


def test_spec_round_trips_through_a_dict() -> None:
    spec = _spec()
    assert StreamSpec.from_dict(spec.to_dict()) == spec


def test_spec_rejects_nonsense() -> None:
    with pytest.raises(ConfigurationError, match="kind"):
        StreamSpec(name="s", kind="video", n_sensors=1, n_markers=1, rate_hz=1, tick_hz=1)  # type: ignore[arg-type]
    with pytest.raises(ConfigurationError, match="positive"):
        StreamSpec(name="s", kind="image2d", n_sensors=1, n_markers=1, rate_hz=0, tick_hz=1)
    with pytest.raises(ConfigurationError, match="incomplete"):
        StreamSpec.from_dict({"name": "s"})


def test_frame_block_checks_shapes_and_joins() -> None:
    a = FrameBlock.empty(3, 2, 3)
    assert len(a) == 0
    b = FrameBlock(
        seq=np.array([7]),
        ticks=np.array([70]),
        arrival_ns=np.array([700]),
        data=np.ones((1, 3, 2, 3)),
        flags=np.ones((1, 3, 2), np.uint8),
        status=np.array([4], np.uint16),
    )
    joined = FrameBlock.concat([a, b, b])
    assert len(joined) == 2
    assert joined.frame(1).seq == 7 and joined.frame(1).status == 4
    with pytest.raises(ConfigurationError, match="flags"):
        FrameBlock(
            seq=np.array([1]),
            ticks=np.array([1]),
            arrival_ns=np.array([1]),
            data=np.ones((1, 3, 2, 3)),
            flags=np.ones((1, 2, 2), np.uint8),
            status=np.array([0], np.uint16),
        )
    with pytest.raises(ConfigurationError, match="different shapes"):
        FrameBlock.concat([a, FrameBlock.empty(1, 1, 1)])
