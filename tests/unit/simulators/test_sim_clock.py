"""Device clock: offset, drift, steps, jitter, u32 wrap — in the ticks the device sends."""

from __future__ import annotations

import csv
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from _simwire import MS, T0, Host, S, cmd, decode, reply_text, spx

from spotlab.core.ticks import unwrap_counter
from spotlab.simulators import wire
from spotlab.simulators.clock import DeviceClock
from spotlab.simulators.selspot import SelspotDevice


def test_offset_and_drift_in_ticks() -> None:
    clock = DeviceClock(offset_s=12.5, drift_ppm=100.0, epoch_ns=T0)
    assert clock.ticks(T0) == 12_500_000
    assert clock.ticks(T0 + 10 * S) == 12_500_000 + 10_001_000
    assert clock.world_to_ticks(np.array([T0, T0 + 10 * S])).tolist() == [12_500_000, 22_501_000]
    back = clock.ticks_to_world_ns(22_501_000)
    assert back == pytest.approx(T0 + 10 * S, abs=1)


def test_negative_drift_and_steps() -> None:
    clock = DeviceClock(drift_ppm=-50.0, steps=[(2.0, 0.25), (1.0, -0.1)], epoch_ns=T0)
    assert clock.ticks(T0 + S - 1) == 999_949  # before the first step
    assert clock.ticks(T0 + round(1.5 * S)) == 1_499_925 - 100_000
    assert clock.ticks(T0 + 3 * S) == 2_999_850 - 100_000 + 250_000
    assert clock.world_to_ticks(np.array([T0 + 3 * S]))[0] == clock.ticks(T0 + 3 * S)


def test_jitter_is_seeded_gaussian() -> None:
    a = DeviceClock(jitter_s=20e-6, seed=4, epoch_ns=T0)
    b = DeviceClock(jitter_s=20e-6, seed=4, epoch_ns=T0)
    xa = np.array([a.jitter() for _ in range(4000)])
    assert xa.tolist()[:5] == [b.jitter() for _ in range(5)]
    assert xa.std() == pytest.approx(20e-6, rel=0.05)
    assert DeviceClock(epoch_ns=T0).jitter() == 0.0
    with pytest.raises(ValueError):
        DeviceClock(jitter_s=-1.0)


def frames_and_truth(
    h: Host, truth: Path, seconds: float
) -> tuple[list[dict[str, object]], list[dict[str, str]]]:
    h.configure(1, 2, 100_000)
    h.buf.clear()
    h.send(cmd("START:"), baud=2_000_000)
    h.wait(round(seconds * S))
    h.dev.close(h.t)
    got = decode(bytes(h.buf))
    frames = [spx(f["payload"]) | {"hflags": f["flags"]} for f in got.frames if f["type"] == 1]  # type: ignore[arg-type]
    rows = list(csv.DictReader(truth.read_text().splitlines()))
    return frames, rows


def test_drift_shows_between_ticks_and_true_time(
    make_device: Callable[..., SelspotDevice], tmp_path: Path
) -> None:
    truth = tmp_path / "t.csv"
    clock = DeviceClock(offset_s=3.0, drift_ppm=200.0, epoch_ns=T0)
    h = Host(make_device(clock=clock, truth=truth))
    frames, rows = frames_and_truth(h, truth, 2.0)
    ticks = np.array([f["tick"] for f in frames], dtype=np.int64)
    assert np.all(np.abs(np.diff(ticks) - 10_000) <= 1)  # the device paces on its own clock
    true_s = np.array([float(r["true_time_s"]) for r in rows])[: len(ticks)]
    slope = np.polyfit(true_s - true_s[0], ticks - ticks[0], 1)[0]
    assert slope == pytest.approx(1e6 * (1 + 200e-6), rel=1e-7)
    assert ticks[0] == pytest.approx(3e6 + (true_s[0] - T0 / 1e9) * 1e6 * (1 + 200e-6), abs=1)


def test_time_probes_follow_the_drift(make_device: Callable[..., SelspotDevice]) -> None:
    clock = DeviceClock(drift_ppm=-300.0, epoch_ns=T0)
    h = Host(make_device(clock=clock))
    h.wait(20 * MS)
    samples = []
    for _ in range(3):
        h.buf.clear()
        t_write = h.t
        h.send(cmd("TIME:"))
        h.wait(100 * MS)
        rx = int(reply_text(bytes(h.buf)).split()[1], 16)
        samples.append((t_write, rx))
        h.wait(5 * S)
    (w0, r0), (w1, r1) = samples[0], samples[-1]
    assert (r1 - r0) / ((w1 - w0) / 1000) == pytest.approx(1 - 300e-6, abs=2e-7)


def test_clock_step_sets_the_resync_flag(
    make_device: Callable[..., SelspotDevice], tmp_path: Path
) -> None:
    truth = tmp_path / "t.csv"
    clock = DeviceClock(steps=[(0.5, 0.2)], epoch_ns=T0)
    h = Host(make_device(clock=clock, truth=truth))
    frames, _ = frames_and_truth(h, truth, 1.0)
    ticks = np.array([f["tick"] for f in frames], dtype=np.int64)
    jumps = np.flatnonzero(np.abs(np.diff(ticks) - 10_000) > 1)
    assert len(jumps) == 1 and ticks[jumps[0] + 1] - ticks[jumps[0]] == pytest.approx(
        210_000, abs=1
    )
    flagged = [i for i, f in enumerate(frames) if f["hflags"] & wire.HEADER_FLAG_CLOCK_RESYNCED]  # type: ignore[operator]
    assert flagged == [jumps[0] + 1]


def test_tick_wraps_at_32_bits(make_device: Callable[..., SelspotDevice], tmp_path: Path) -> None:
    truth = tmp_path / "t.csv"
    clock = DeviceClock(offset_s=2**32 / 1e6 - 0.3, epoch_ns=T0)  # wraps 0.3 s after power-up
    h = Host(make_device(clock=clock, truth=truth))
    frames, rows = frames_and_truth(h, truth, 1.0)
    raw = np.array([f["tick"] for f in frames], dtype=np.int64)
    assert raw.max() > 2**32 - 20_000 and raw.min() < 20_000
    unwrapped = unwrap_counter(raw, 32)
    assert np.all(np.abs(np.diff(unwrapped) - 10_000) <= 1)
    assert [int(r["device_tick"]) for r in rows[: len(raw)]] == raw.tolist()
    assert int(rows[-1]["device_us"]) > 2**32


def test_jitter_scatters_truth_around_ticks(
    make_device: Callable[..., SelspotDevice], tmp_path: Path
) -> None:
    truth = tmp_path / "t.csv"
    clock = DeviceClock(jitter_s=50e-6, seed=2, epoch_ns=T0)
    h = Host(make_device(clock=clock, truth=truth))
    _, rows = frames_and_truth(h, truth, 2.0)
    resid_us = np.array(
        [float(r["true_time_s"]) * 1e6 - T0 / 1e3 - int(r["device_us"]) for r in rows]
    )
    assert resid_us.std() == pytest.approx(50, rel=0.25)
    assert abs(resid_us.mean()) < 15
