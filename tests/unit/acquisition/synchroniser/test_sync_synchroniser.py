"""Synchroniser: streams of different rates and families on one time base."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose

from spotlab.acquisition.synchroniser import (
    LOST_FRAMES,
    OUTSIDE,
    TIME_GAP,
    StreamInput,
    Synchroniser,
)
from spotlab.core import StreamSpec, SynchronisationError


def signal(t: np.ndarray) -> np.ndarray:
    """A smooth movement, mm."""
    return 100.0 * np.sin(2 * np.pi * 1.3 * t) + 40.0 * np.cos(2 * np.pi * 0.7 * t)


def make(
    name: str, kind: str, rate: float, t0: float, n: int, m: int, slot: float | None = None
) -> tuple[StreamSpec, np.ndarray, np.ndarray, np.ndarray]:
    spec = StreamSpec(name, kind, 2, m, rate, 1e6, slot_period_s=slot)  # type: ignore[arg-type]
    t = t0 + np.arange(n) / rate
    off = np.zeros(m) if slot is None else (np.arange(m) + 0.5) * slot
    ts = t[:, None] + off
    data = np.stack([signal(ts), 2.0 * signal(ts)], axis=-1)[:, :, None, :]  # (F, M, 1, 2)
    data = np.repeat(data, 2, axis=2)  # (F, M, S=2, V=2)
    return spec, np.arange(n), t, data


def three_streams() -> list[StreamInput]:
    a = make("optotrak", "point3d", 100.0, 0.013, 200, 3)
    b = make("selspot", "image2d", 300.0, 0.0021, 600, 8, slot=100e-6)
    c = make("video", "blobs2d", 60.0, 0.0, 121, 2)
    return [StreamInput(*a), StreamInput(*b), StreamInput(*c)]


def test_three_rates_and_families_on_the_fastest_rate_within_the_overlap() -> None:
    sync = Synchroniser(three_streams())
    assert sync.names == ["optotrak", "selspot", "video"]
    out = sync.resample()
    t = out.times
    assert_allclose(np.diff(t), 1 / 300.0, rtol=1e-9)
    # Overlap: every sample of every stream has begun and none has ended.
    assert t[0] == pytest.approx(max(0.013, 0.0021 + 7.5 * 100e-6, 0.0))
    assert t[-1] <= min(0.013 + 1.99, 0.0021 + 599 / 300.0, 2.0) + 1e-12
    for name, res in out.streams.items():
        assert np.all(res.valid), name
        want = signal(t)[:, None, None]
        assert_allclose(res.values[..., 0], np.broadcast_to(want, res.values.shape[:-1]), atol=0.02)
        assert_allclose(res.values[..., 1], 2.0 * res.values[..., 0], atol=1e-9)
        st = out.stats[name]
        assert st.lost_frames == 0 and st.time_gaps == 0 and st.missing_runs == 0
        assert st.valid_fraction == 1.0
    assert out.stats["video"].rate_hz == pytest.approx(60.0)
    assert out.stats["selspot"].kind == "image2d" and out.stats["selspot"].n_frames == 600


def test_union_span_flags_what_lies_beyond_a_stream() -> None:
    out = Synchroniser(three_streams()).resample(rate_hz=100.0, span="union")
    assert out.times[0] == pytest.approx(0.0)
    assert_allclose(np.diff(out.times), 0.01, rtol=1e-9)
    opt = out.streams["optotrak"]
    early = out.times < 0.013
    assert early.any() and np.all(opt.flags[early] == OUTSIDE)
    assert np.all(np.isnan(opt.values[early]))
    assert out.stats["optotrak"].valid_fraction < 1.0


def test_given_instants_and_a_gap_in_one_stream_only() -> None:
    streams = three_streams()
    spec, seq, t, data = make("selspot", "image2d", 300.0, 0.0021, 600, 8, slot=100e-6)
    keep = np.r_[0:300, 310:600]  # 10 frames lost
    data = data.copy()
    data[400:420, 3, 1, :] = np.nan  # marker 3 occluded in camera 1
    t_stall = t[keep].copy()
    t_stall[450:] += 0.05  # then a stall of 50 ms (seq contiguous)
    streams[1] = StreamInput(spec, seq[keep], t_stall, data[keep])
    u = np.linspace(0.1, 1.9, 500)
    out = Synchroniser(streams).resample(u)
    sel = out.streams["selspot"]
    st = out.stats["selspot"]
    assert st.lost_frames == 10 and st.time_gaps == 1 and st.missing_runs == 2
    lost = (u > t[299] + 1e-3) & (u < t[310])
    assert lost.any() and np.all(sel.flags[lost] == LOST_FRAMES)
    stall = (u > t_stall[449] + 1e-3) & (u < t_stall[450])
    assert stall.any() and np.all(sel.flags[stall] == TIME_GAP)
    # The other streams do not notice.
    assert np.all(out.streams["optotrak"].valid) and np.all(out.streams["video"].valid)
    # The occluded channel only: marker 3, camera 1.
    hidden = ~sel.valid[:, 3, 1, 0] & ~lost & ~stall
    assert hidden.any() and np.all(sel.valid[hidden][:, [0, 1, 2, 4, 5, 6, 7]])


def test_without_slot_correction_every_marker_is_taken_at_its_frame_time() -> None:
    streams = three_streams()[1:2]
    with_slots = Synchroniser(streams).resample(rate_hz=300.0)
    without = Synchroniser(streams, slot_correction=False).resample(with_slots.times)
    lag = without.streams["selspot"].values[:, 7, 0, 0] - signal(with_slots.times)
    speed = np.gradient(signal(with_slots.times), with_slots.times)
    assert_allclose(lag, speed * 7.5 * 100e-6, atol=0.01, rtol=0.01)
    err = with_slots.streams["selspot"].values[:, 7, 0, 0] - signal(with_slots.times)
    assert np.max(np.abs(err)) < 0.02


def test_clock_rate_scales_the_largest_frame_interval() -> None:
    spec, seq, t, data = make("a", "point3d", 100.0, 0.0, 50, 1)
    t = t * 1.6  # a clock that runs 1.6 times slow: intervals of 16 ms
    assert Synchroniser([StreamInput(spec, seq, t, data)]).resample().stats["a"].time_gaps == 49
    out = Synchroniser([StreamInput(spec, seq, t, data, clock_rate=1.6)]).resample()
    assert out.stats["a"].time_gaps == 0


def test_bad_streams_are_named() -> None:
    spec, seq, t, data = make("opto", "point3d", 100.0, 0.0, 20, 3)
    with pytest.raises(SynchronisationError, match="no stream"):
        Synchroniser([])
    with pytest.raises(SynchronisationError, match="repeated: \\['opto'\\]"):
        Synchroniser([StreamInput(spec, seq, t, data), StreamInput(spec, seq, t, data)])
    with pytest.raises(SynchronisationError, match="'opto': data has 2 markers, the spec 3"):
        Synchroniser([StreamInput(spec, seq, t, data[:, :2])])
    with pytest.raises(SynchronisationError, match="'opto': data must have shape"):
        Synchroniser([StreamInput(spec, seq, t, data[:-1])])
    back = seq.copy()
    back[10] = 3
    with pytest.raises(SynchronisationError, match="'opto': seq does not increase at frame 10"):
        Synchroniser([StreamInput(spec, back, t, data)])
    jump = t.copy()
    jump[12] = jump[5]
    with pytest.raises(SynchronisationError, match="'opto': frame times do not increase"):
        Synchroniser([StreamInput(spec, seq, jump, data)])
    with pytest.raises(SynchronisationError, match=r"'opto': .*at least 2 frames"):
        Synchroniser([StreamInput(spec, seq[:0], t[:0], data[:0])])
    with pytest.raises(SynchronisationError, match="max_gap_periods"):
        Synchroniser([StreamInput(spec, seq, t, data)], max_gap_periods=1.0)


def test_bad_spans_and_rates() -> None:
    a = make("a", "point3d", 100.0, 0.0, 20, 1)
    b = make("b", "point3d", 100.0, 5.0, 20, 1)
    sync = Synchroniser([StreamInput(*a), StreamInput(*b)])
    with pytest.raises(SynchronisationError, match="do not overlap"):
        sync.resample()
    assert sync.resample(span="union").times.size == 520
    with pytest.raises(SynchronisationError, match="span must be"):
        sync.instants(span="both")  # type: ignore[arg-type]
    with pytest.raises(SynchronisationError, match="rate must be finite and positive"):
        sync.instants(rate_hz=0.0)
    assert_allclose(sync.instants(50.0, start=1.0, stop=1.1), [1.0, 1.02, 1.04, 1.06, 1.08, 1.1])
