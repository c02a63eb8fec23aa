"""Pairing device frames with the timer's edges of their frame pulses.

The counting argument and the arrival-envelope offset are described in
:mod:`spotlab.acquisition.timebase`, which uses these helpers.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.ndimage import minimum_filter1d
from scipy.stats import theilslopes

from spotlab.acquisition.recorded_frames import DeviceFrames, TimerFrames
from spotlab.core.streams import StreamSpec

I64 = npt.NDArray[np.int64]
F64 = npt.NDArray[np.float64]
B = npt.NDArray[np.bool_]

SEQ_RUN = 1 << 16
#: Seconds of frames over which the lower envelope of the arrivals is taken.
ENVELOPE_S = 2.0


def host_times(ticks: I64, arrival_ns: I64, tick_hz: float, rate_hz: float) -> F64:
    """Earliest-delivery host time of each frame, s: a line through the arrivals lowered
    to their running minimum over :data:`ENVELOPE_S` (robust to steps elsewhere)."""
    n = ticks.shape[0]
    arr = (arrival_ns - arrival_ns[0]).astype(np.float64) * 1e-9
    x = (ticks - ticks[0]).astype(np.float64) / tick_hz
    resid = arr - x
    size = int(max(3, min(n, ENVELOPE_S * rate_hz)))
    # rate of the device clock against the host: robust line through the window minima
    starts = np.arange(0, n, size)
    lows = np.array([s + int(np.argmin(resid[s : s + size])) for s in starts])
    slope = 0.0
    if lows.shape[0] >= 3:
        slope = float(theilslopes(resid[lows], x[lows])[0])
        if not (math.isfinite(slope) and abs(slope) < 0.01):
            slope = 0.0
    resid = resid - slope * x
    envelope = minimum_filter1d(resid, size=size, mode="nearest")
    return np.asarray((1.0 + slope) * x + envelope + arrival_ns[0] * 1e-9, dtype=np.float64)


def delivery_delay_s(spec: StreamSpec) -> float:
    """Seconds from a frame's tick to the earliest it can reach the host, as its stream
    declares them: the acquisition span of time-multiplexed slots, plus the spec's
    ``metadata["frame_delay_s"]`` (a family whose frame leaves well after its tick: a
    scanner's sweep and its frame's transmission) when there is one."""
    delay = spec.metadata.get("frame_delay_s")
    extra = float(delay) if isinstance(delay, (int, float)) and math.isfinite(delay) else 0.0
    return (spec.slot_period_s or 0.0) * spec.n_markers + max(extra, 0.0)


def _frame_index(seq: I64, ticks: I64, period_ticks: float) -> I64:
    """Frame periods since the first frame: seq steps, or more where the ticks show frames
    the device dropped itself (a tick step within 10 % of a whole number of periods)."""
    if seq.shape[0] == 0:
        return seq.copy()
    ds = np.diff(seq)
    periods = np.diff(ticks) / period_ticks
    whole = np.round(periods)
    dropped = (np.abs(periods - whole) < 0.1) & (whole > ds)
    steps = np.where(dropped, whole.astype(np.int64), ds)
    return np.concatenate([[0], np.cumsum(steps)]).astype(np.int64)


def _pulse_index(edge_index: I64) -> I64:
    """Pulse number of rising edges in one timer run (edge_index counts both polarities
    when the input is armed for both: steps of 2)."""
    if edge_index.shape[0] < 2:
        return edge_index.copy()
    d = np.diff(edge_index)
    step = int(np.min(d[d > 0])) if np.any(d > 0) else 1
    return (edge_index - edge_index[0]) // max(step, 1)


@dataclass(frozen=True)
class ChannelEdges:
    pulse: I64  # pulse number, made increasing over timer runs
    tick: I64
    host_s: F64


def channel_edges(timer: TimerFrames, channel: int, timer_host: F64) -> ChannelEdges | None:
    keep = (timer.edge_input == channel) & timer.edge_rising
    if int(keep.sum()) < 3:
        return None
    idx = timer.edge_index[keep]
    tick = timer.edge_tick[keep]
    runs = np.concatenate([[0], np.cumsum(np.diff(idx) < 0)])
    pulse = np.empty_like(idx)
    for r in np.unique(runs):
        sel = runs == r
        pulse[sel] = _pulse_index(idx[sel]) + int(r) * (1 << 40)
    host = np.interp(tick.astype(np.float64), timer.ticks.astype(np.float64), timer_host)
    return ChannelEdges(pulse, tick, host)


def _nearest(sorted_x: F64, x: F64) -> npt.NDArray[np.intp]:
    pos = np.clip(np.searchsorted(sorted_x, x), 1, max(sorted_x.shape[0] - 1, 1))
    lo = pos - 1
    hi = np.minimum(pos, sorted_x.shape[0] - 1)
    return np.where(np.abs(sorted_x[hi] - x) < np.abs(sorted_x[lo] - x), hi, lo)


@dataclass(frozen=True)
class PulsedDevice:
    frames: DeviceFrames
    host: F64  # earliest-delivery host time of the frame's first sample, s
    index: I64  # frame periods since the run's first frame
    run: I64
    period_s: float


def pulsed_device(frames: DeviceFrames) -> PulsedDevice:
    spec = frames.spec
    tk = frames.ticks
    period_ticks = spec.tick_hz / spec.rate_hz
    if tk.shape[0] > 1:
        d = np.diff(tk)[np.diff(frames.seq) == 1]
        d = d[d > 0]
        if d.size:
            period_ticks = float(np.median(d))
    host = host_times(tk, frames.arrival_ns, spec.tick_hz, spec.tick_hz / period_ticks)
    host -= delivery_delay_s(spec)
    run = frames.seq // SEQ_RUN
    index = np.empty_like(frames.seq)
    for r in np.unique(run):
        sel = run == r
        index[sel] = _frame_index(frames.seq[sel], tk[sel], period_ticks) + int(r) * (1 << 40)
    return PulsedDevice(frames, host, index, run, period_ticks / spec.tick_hz)


def _score(dev: PulsedDevice, edges: ChannelEdges) -> float:
    """How well a channel's edges follow a device's frames in host time, -inf..1."""
    j = _nearest(edges.host_s, dev.host)
    d = edges.host_s[j] - dev.host
    med = float(np.median(d))
    consistent = float(np.mean(np.abs(d - med) < dev.period_s / 8))
    return consistent - abs(med) / dev.period_s


def frame_edge_pairs(
    dev: PulsedDevice, edges: ChannelEdges
) -> tuple[npt.NDArray[np.intp], npt.NDArray[np.intp]]:
    """Indices (frames, edges) of the frames paired with their own edge."""
    j = _nearest(edges.host_s, dev.host)
    d = edges.host_s[j] - dev.host
    near = np.abs(d) < dev.period_s / 2
    k_of = dev.index - edges.pulse[j]
    frames_out: list[npt.NDArray[np.intp]] = []
    edges_out: list[npt.NDArray[np.intp]] = []
    order = np.argsort(edges.pulse, kind="stable")
    sorted_pulse = edges.pulse[order]
    for r in np.unique(dev.run):
        sel = (dev.run == r) & near
        if not np.any(sel):
            continue
        values, counts = np.unique(k_of[sel], return_counts=True)
        k = int(values[np.argmax(counts)])
        rows = np.flatnonzero(dev.run == r)
        want = dev.index[rows] - k
        pos = np.clip(np.searchsorted(sorted_pulse, want), 0, sorted_pulse.shape[0] - 1)
        hit = sorted_pulse[pos] == want
        frames_out.append(rows[hit])
        edges_out.append(order[pos[hit]])
    if not frames_out:
        empty = np.zeros(0, dtype=np.intp)
        return empty, empty.copy()
    return np.concatenate(frames_out), np.concatenate(edges_out)


def assign_channels(
    devices: Mapping[str, PulsedDevice],
    channels: Mapping[int, ChannelEdges],
    wiring: Mapping[str, int],
    notes: list[str],
) -> dict[str, int]:
    out: dict[str, int] = {}
    for name, ch in wiring.items():
        if name not in devices:
            notes.append(f"--wiring names stream {name!r}, which the recording does not hold")
        elif ch not in channels:
            notes.append(f"stream {name!r}: timer input {ch} captured no edges")
        else:
            out[name] = ch
    scores = [
        (_score(dev, edges), name, ch)
        for name, dev in devices.items()
        if name not in out
        for ch, edges in channels.items()
        if ch not in out.values()
    ]
    for score, name, ch in sorted(scores, reverse=True):
        if score > 0.5 and name not in out and ch not in out.values():
            out[name] = ch
            rivals = [s for s, n, c in scores if n == name and c != ch and s > score - 0.25]
            if rivals:
                notes.append(
                    f"stream {name!r}: timer input {ch} chosen by its edges' phase in host "
                    "time, but another input follows it nearly as well (systems started "
                    f"together at one rate); give the wiring ({name}=INPUT) if it is wrong"
                )
    return out


# -- per-stream times -----------------------------------------------------------------
