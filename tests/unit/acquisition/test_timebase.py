"""Session time base from timer edges, on synthetic frames with a known truth."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pytest

from spotlab.acquisition.timebase import DeviceFrames, TimerFrames, session_timebase
from spotlab.core.errors import SynchronisationError
from spotlab.core.streams import StreamSpec

F64 = npt.NDArray[np.float64]
RATE = 100.0


def spec(name: str) -> StreamSpec:
    return StreamSpec(name, "image2d", 1, 8, RATE, 1e6, slot_period_s=100e-6)


def device(
    name: str,
    t_true: F64,
    offset_s: float,
    drift_ppm: float,
    rng: np.random.Generator,
    step: tuple[float, float] | None = None,
) -> DeviceFrames:
    dev_s = offset_s + (t_true - t_true[0]) * (1 + drift_ppm * 1e-6)
    if step is not None:
        dev_s = dev_s + np.where(t_true >= step[0], step[1], 0.0)
    ticks = np.floor(dev_s * 1e6 + 1e-4).astype(np.int64)
    # last byte of the frame: 8 slots of 100 us, then transmission and host queueing
    arrival = t_true + 0.8e-3 + 0.3e-3 + rng.exponential(0.5e-3, t_true.shape)
    seq = np.arange(t_true.shape[0], dtype=np.int64)
    return DeviceFrames(name, seq, ticks, np.round(arrival * 1e9).astype(np.int64), spec(name))


def timer(
    t_start: float, t_end: float, pulses: dict[int, F64], rng: np.random.Generator
) -> TimerFrames:
    def counter(t: F64) -> npt.NDArray[np.int64]:
        return np.round((1000.0 + t * (1 + 30e-6)) * 1e7).astype(np.int64)

    t_frames = np.arange(t_start, t_end, 1 / RATE)
    ticks = counter(t_frames)
    arrival = t_frames + 0.3e-3 + rng.exponential(0.3e-3, t_frames.shape)
    ch, idx, tk = [], [], []
    for c, t in pulses.items():
        inside = (t >= t_start) & (t < t_end)
        ch.append(np.full(int(inside.sum()), c))
        idx.append(np.flatnonzero(inside) - np.flatnonzero(inside)[0])
        tk.append(counter(t[inside]))
    return TimerFrames(
        "timer",
        np.arange(t_frames.shape[0], dtype=np.int64),
        ticks,
        np.round(arrival * 1e9).astype(np.int64),
        np.concatenate(ch).astype(np.int64),
        np.concatenate(idx).astype(np.int64),
        np.concatenate(tk),
        np.ones(sum(c.shape[0] for c in ch), dtype=bool),
    )


def max_affine_error(times: list[F64], truths: list[F64]) -> float:
    s, t = np.concatenate(times), np.concatenate(truths)
    a = np.c_[t - t.mean(), np.ones_like(t)]
    return float(np.max(np.abs(s - a @ np.linalg.lstsq(a, s, rcond=None)[0])))


def test_frames_lost_edges_lost_and_a_step_stay_within_a_microsecond() -> None:
    rng = np.random.default_rng(1)
    ta = 5.0 + 0.0031 + np.arange(1000) / RATE / (1 + 200e-6)
    tb = 5.0 + 0.0007 + np.arange(1000) / RATE / (1 - 150e-6)
    a = device("a", ta, 3.0, 200, rng, step=(9.0, 2.5e-3))
    b = device("b", tb, 40.0, -150, rng)
    tim = timer(5.5, 14.5, {0: ta, 1: tb}, rng)
    # frames lost on the link (seq gaps) and edges lost (edge_index gaps)
    keep_a = np.ones(1000, bool)
    keep_a[[100, 101, 500]] = False
    a = DeviceFrames("a", a.seq[keep_a], a.ticks[keep_a], a.arrival_ns[keep_a], a.spec)
    ta = ta[keep_a]
    keep_e = np.ones(len(tim.edge_tick), bool)
    keep_e[[10, 11, 12, 400]] = False
    tim = TimerFrames(
        tim.name, tim.seq, tim.ticks, tim.arrival_ns, tim.edge_input[keep_e],
        tim.edge_index[keep_e], tim.edge_tick[keep_e], tim.edge_rising[keep_e],
    )  # fmt: skip
    tb_ = session_timebase([a, b], tim, {"a": 0, "b": 1})
    sa, sb = tb_.streams["a"], tb_.streams["b"]
    assert sa.channel == 0 and sb.channel == 1
    assert [e.kind for e in sa.model.events] == ["step"]  # type: ignore[union-attr]
    assert abs(sa.model.events[0].size_s - 2.5e-3) < 2e-6  # type: ignore[union-attr]
    assert set(sa.method) == {"edge", "model", "extrapolated"}
    inside = sa.method != "extrapolated"
    err = max_affine_error(
        [sa.time_s[inside], sb.time_s[sb.method != "extrapolated"]],
        [ta[inside], tb[sb.method != "extrapolated"]],
    )
    assert err < 1e-6, err
    report = tb_.report()
    assert report["reference"] == "timer"
    assert abs(report["streams"][1]["drift_ppm"] - 170) < 1


def test_device_without_input_falls_back_to_arrivals_and_says_so() -> None:
    rng = np.random.default_rng(2)
    ta = 5.0 + np.arange(600) / RATE
    tim = timer(5.0, 11.0, {0: ta}, rng)
    tb = 5.002 + np.arange(600) / RATE
    b = device("b", tb, 40.0, -150, rng)
    a = device("a", ta, 3.0, 200, rng)
    out = session_timebase([a, b], tim)
    assert out.streams["a"].channel == 0
    assert set(out.streams["b"].method) == {"arrivals"}
    assert any("arrival stamps" in n for n in out.streams["b"].notes)
    # arrival times: within a few ms of the truth, on the same session scale
    err = max_affine_error([out.streams["b"].time_s], [tb])
    assert err < 3e-3


def test_timer_counter_going_back_is_refused() -> None:
    rng = np.random.default_rng(3)
    ta = 5.0 + np.arange(300) / RATE
    tim = timer(5.0, 8.0, {0: ta}, rng)
    ticks = tim.ticks.copy()
    ticks[100:] -= 10**7
    bad = TimerFrames(tim.name, tim.seq, ticks, tim.arrival_ns, tim.edge_input,
                      tim.edge_index, tim.edge_tick, tim.edge_rising)  # fmt: skip
    with pytest.raises(SynchronisationError, match="counter does not increase at frame seq 100"):
        session_timebase([device("a", ta, 3.0, 0, rng)], bad)


def test_no_timer_gives_host_times_and_a_note() -> None:
    rng = np.random.default_rng(4)
    t = 5.0 + np.arange(300) / RATE
    out = session_timebase([device("a", t, 3.0, 100, rng)], None, {"a": 0})
    assert out.reference == "host"
    assert any("no timer stream" in n for n in out.notes)
    assert any("ignored" in n for n in out.notes)
    assert np.all(np.diff(out.streams["a"].time_s) > 0)


def test_a_device_catching_up_never_runs_frame_times_backwards() -> None:
    # An in-process simulator starved at start-up (a console trial under load,
    # 2026-11-25) delivers its backlog in bursts: arrivals wander by +-0.1 s about the
    # ticks and gain 0.8 s over 5.8 s. The steps the arrival fit saw in that made its
    # segments' lines cross: frame times ran back by 0.22 s and the export failed.
    rng = np.random.default_rng(19)
    t = 5.0 + np.arange(584) / RATE
    a = device("a", t, 3.0, 0, rng)
    wander = np.cumsum(rng.normal(0.0, 0.012, t.shape)) - 0.14 * (t - t[0])
    arrival = a.arrival_ns + np.round(wander * 1e9).astype(np.int64)
    a = DeviceFrames("a", a.seq, a.ticks, arrival, a.spec)
    out = session_timebase([a], None, {})
    assert np.all(np.diff(out.streams["a"].time_s) > 0)
    assert any("one line per clock epoch" in n for n in out.streams["a"].notes)


def test_a_stream_declares_how_late_its_frames_leave() -> None:
    """A scanner's frame leaves after its sweep and transmission (``frame_delay_s``); a
    time-multiplexed one after its slots; both are taken off the arrival envelope."""
    from spotlab.acquisition._frame_pulses import delivery_delay_s

    scan = StreamSpec(
        name="coda", kind="scan3", n_sensors=1, n_markers=4, rate_hz=300.0, tick_hz=1e6,
        metadata={"frame_delay_s": 0.004},
    )  # fmt: skip
    assert delivery_delay_s(scan) == 0.004
    slots = StreamSpec(
        name="spx", kind="image2d", n_sensors=2, n_markers=8, rate_hz=100.0, tick_hz=1e6,
        slot_period_s=1e-4, metadata={"frame_delay_s": "soon"},
    )  # fmt: skip
    assert delivery_delay_s(slots) == pytest.approx(8e-4)
