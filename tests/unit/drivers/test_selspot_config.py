"""SPX configuration: ranges, the START: timing and bandwidth checks, wire form."""

from __future__ import annotations

import pytest

from spotlab.core.errors import BandwidthError, ConfigurationError
from spotlab.drivers.mcs1.commands import encode_command
from spotlab.drivers.selspot import SelspotConfig
from spotlab.drivers.selspot.config import led_table


def test_spec_example_needs_comm_8() -> None:
    # selspot.md §2: 4 cameras x 32 LEDs at 200 Hz needs 1.336 Mbit/s: COMM:8 or faster.
    cfg = SelspotConfig.create(cameras=4, leds=32, rate_hz=200, baud=2_000_000)
    assert cfg.frame_bytes == 668 and cfg.payload_len == 656
    assert cfg.line_bits_per_s == 1_336_000
    assert cfg.fits(2_000_000) and not cfg.fits(1_000_000)
    with pytest.raises(BandwidthError) as info:
        SelspotConfig.create(cameras=4, leds=32, rate_hz=200, baud=1_000_000)
    message = str(info.value)
    assert "1.336 Mbit/s" in message
    assert "baud=2000000" in message
    assert "1000000 baud" in message
    assert "119.76 Hz or less" in message  # 80 * baud / 668 bytes, in mHz


def test_bandwidth_limit_is_exact() -> None:
    # rate * bytes * 10 <= 0.8 * baud: 33-byte frames at 9600 baud -> 23.27 Hz at most
    ok = SelspotConfig.create(cameras=1, leds=1, rate_hz=23.272, baud=9600)
    assert ok.fits(9600)
    with pytest.raises(BandwidthError):
        SelspotConfig.create(cameras=1, leds=1, rate_hz=23.28, baud=9600)


def test_bandwidth_beyond_every_rate_says_so() -> None:
    with pytest.raises(BandwidthError, match="no MCS-1 rate carries it"):
        SelspotConfig.create(cameras=4, leds=128, rate_hz=150, slot_us=50, baud="auto")


def test_auto_baud_picks_the_slowest_rate_that_fits() -> None:
    assert SelspotConfig.create(cameras=4, leds=32, rate_hz=200, baud="auto").baud == 2_000_000
    assert SelspotConfig.create(cameras=1, leds=1, rate_hz=10, baud="auto").baud == 9_600
    # 108-byte frames at 100 Hz: 108 kbit/s, 135 kbaud with the reserve
    assert SelspotConfig.create(cameras=2, leds=8, rate_hz=100, baud="auto").baud == 921_600
    assert SelspotConfig.create(cameras=1, leds=8, rate_hz=100, baud="auto").baud == 115_200


def test_bandwidth_error_is_a_configuration_error() -> None:
    assert issubclass(BandwidthError, ConfigurationError)


def test_timing_check() -> None:
    # 1/rate >= (N + 1 + b) * slot; 32 LEDs at 100 us: 3300 us -> 303 Hz at most
    SelspotConfig.create(leds=32, rate_hz=303, baud=3_000_000)
    with pytest.raises(ConfigurationError, match=r"303\.03 Hz or less") as info:
        SelspotConfig.create(leds=32, rate_hz=304, baud=3_000_000)
    assert "33 slots of 100 µs" in str(info.value)
    assert "99 µs or less" in str(info.value)
    assert not isinstance(info.value, BandwidthError)


def test_timing_counts_the_dark_slot_of_bgnd_2() -> None:
    SelspotConfig.create(leds=8, slot_us=1000, rate_hz=111, bgnd=1, baud="auto")
    with pytest.raises(ConfigurationError, match="dark slot"):
        SelspotConfig.create(leds=8, slot_us=1000, rate_hz=101, bgnd=2, baud="auto")


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"cameras": 0}, "cameras must be 1-4"),
        ({"cameras": 5}, "cameras must be 1-4"),
        ({"leds": 0}, "1-128 entries"),
        ({"leds": 129}, "1-128 entries"),
        ({"leds": [1, 2, 1]}, r"listed twice: \[1\]"),
        ({"leds": [128]}, "ids must be 0-127"),
        ({"leds": [(1, 256)]}, "currents must be 0-255"),
        ({"leds": [(1, 2, 3)]}, "neither an id nor"),
        ({"leds": True}, "count or a list"),
        ({"slot_us": 49}, "slot_us must be 50-1000"),
        ({"slot_us": 1001}, "slot_us must be 50-1000"),
        ({"rate_hz": 0.5}, "1-10000 Hz"),
        ({"rate_hz": 10_001}, "1-10000 Hz"),
        ({"rate_hz": float("nan")}, "finite"),
        ({"bgnd": 3}, "bgnd must be 0, 1 or 2"),
        ({"agc": 0}, "AGC target"),
        ({"agc": 256}, "AGC target"),
        ({"baud": 12345}, "baud must be one of"),
        ({"baud": "fast"}, "or 'auto'"),
    ],
)
def test_out_of_range_values_are_named(kwargs: dict[str, object], match: str) -> None:
    with pytest.raises(ConfigurationError, match=match):
        SelspotConfig.create(**kwargs)  # type: ignore[arg-type]


def test_led_table_forms() -> None:
    assert led_table(3) == ((0, 0x80), (1, 0x80), (2, 0x80))
    assert led_table([5, 9]) == ((5, 0x80), (9, 0x80))
    assert led_table([(0, 0x80), [5, 0xC0]]) == ((0, 0x80), (5, 0xC0))


def test_commands_match_golden_vectors() -> None:
    cfg = SelspotConfig.create(
        cameras=2, leds=[(0, 0x80), (5, 0xC0), (17, 0x40)], rate_hz=200, agc=160
    )
    wire = [encode_command(v, a) for v, a in cfg.commands()]
    assert wire == [
        b"CAMS:2BD12\r",
        b"LEDT:008005C01140E8FF\r",
        b"SLOT:1000B9E\r",
        b"RATE:2000008EC6\r",
        b"BGND:1587B\r",
        b"AGC:1,1608496\r",
    ]
    off = SelspotConfig.create(leds=1)
    assert off.commands()[-1] == ("AGC", "0,160")


def test_dict_round_trip() -> None:
    cfg = SelspotConfig.create(cameras=3, leds=[(4, 10), (7, 200)], rate_hz=123.456, agc=90)
    assert cfg.rate_mhz == 123_456
    assert SelspotConfig.from_dict(cfg.to_dict()) == cfg
    assert SelspotConfig.from_dict({}) == SelspotConfig()
    with pytest.raises(ConfigurationError, match="malformed"):
        SelspotConfig.from_dict({"cameras": "two"})
    with pytest.raises(ConfigurationError):
        SelspotConfig.from_dict({"leds": [[1, 2, 3]]})
