"""Synthetic device clocks with known truth, for tests and benchmarks.

Numerics only (no threads, no world clock): a device clock is a function of the true
session time t, s:

``device_s(t) = offset_s + (1 + drift_ppm 1e-6) (t - t_r) + steps due by t``

where ``t_r`` is the last reset before t (0 before any; each reset restarts the counter
at its own offset). Ticks are ``floor(tick_hz * device_s)``; a wrap glitch adds
``cycles * 2**bits`` ticks from its instant on (an unwrapper that missed or added a
wrap).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

I64 = npt.NDArray[np.int64]
F64 = npt.NDArray[np.float64]


@dataclass(frozen=True)
class SyntheticClock:
    """A device clock with offset, drift, steps, resets and wrap glitches.

    Attributes
    ----------
    tick_hz : float
        Nominal tick rate, Hz.
    offset_s : float
        Device time at t = 0, s.
    drift_ppm : float
        Oscillator error, ppm (positive: fast).
    steps : sequence of (float, float)
        ``(at_s, delta_s)``: from true time ``at_s`` the counter reads ``delta_s`` more.
    resets : sequence of (float, float)
        ``(at_s, new_offset_s)``: the counter restarts at ``new_offset_s``.
    wraps : sequence of (float, int, int)
        ``(at_s, cycles, bits)``: from ``at_s`` the ticks carry ``cycles * 2**bits`` more.
    """

    tick_hz: float = 1e6
    offset_s: float = 0.0
    drift_ppm: float = 0.0
    steps: Sequence[tuple[float, float]] = ()
    resets: Sequence[tuple[float, float]] = ()
    wraps: Sequence[tuple[float, int, int]] = ()

    def device_s(self, t: npt.ArrayLike) -> F64:
        """Device time, s, at true times ``t``, shape preserved."""
        tt = np.asarray(t, dtype=np.float64)
        start = np.zeros_like(tt)
        base = np.full_like(tt, self.offset_s)
        for at, new_offset in sorted(self.resets):
            after = tt >= at
            start[after] = at
            base[after] = new_offset
        out = base + (tt - start) * (1.0 + self.drift_ppm * 1e-6)
        for at, delta in self.steps:
            out = out + np.where(tt >= at, delta, 0.0)
        return np.asarray(out, dtype=np.float64)

    def ticks(self, t: npt.ArrayLike) -> I64:
        """Device ticks (int64) at true times ``t``."""
        tt = np.asarray(t, dtype=np.float64)
        out = np.floor(self.device_s(tt) * self.tick_hz).astype(np.int64)
        for at, cycles, bits in self.wraps:
            out = out + np.where(tt >= at, np.int64(cycles) << np.int64(bits), 0)
        return np.asarray(out, dtype=np.int64)


def frame_times(
    n: int, rate_hz: float, start_s: float = 0.5, seed: int = 0, jitter_s: float = 0.0
) -> F64:
    """True times of n frames at ``rate_hz`` from ``start_s``, shape (n,).

    A random phase, plus Gaussian trigger jitter of ``jitter_s`` RMS per frame.
    """
    rng = np.random.default_rng(seed)
    t = start_s + rng.uniform(0.0, 1.0 / rate_hz) + np.arange(n) / rate_hz
    return np.asarray(t + rng.normal(0.0, jitter_s, n) if jitter_s > 0 else t)


def timer_reference(t: npt.ArrayLike, resolution_s: float = 1e-7) -> F64:
    """Reference edge times as a timer of ``resolution_s`` ticks reads them (floor), s."""
    return np.asarray(np.floor(np.asarray(t) / resolution_s) * resolution_s, dtype=np.float64)


def arrival_times(
    t: npt.ArrayLike, latency_s: float = 200e-6, mean_queue_s: float = 1e-3, seed: int = 0
) -> F64:
    """Host arrival times: fixed latency plus exponential queueing delay, s."""
    tt = np.asarray(t, dtype=np.float64)
    rng = np.random.default_rng(seed)
    return np.asarray(tt + latency_s + rng.exponential(mean_queue_s, tt.shape))


@dataclass(frozen=True)
class ProbeLog:
    """Probe exchanges: host send/receive seconds, device receive/send ticks, shapes (N,)."""

    t0_s: F64
    t1_ticks: I64
    t2_ticks: I64
    t3_s: F64


def probe_exchanges(
    clock: SyntheticClock,
    duration_s: float,
    *,
    every_s: float = 2.0,
    burst: int = 8,
    spacing_s: float = 0.064,
    up_s: tuple[float, float] = (100e-6, 200e-6),
    down_s: tuple[float, float] = (100e-6, 200e-6),
    turnaround_s: float = 20e-6,
    seed: int = 0,
) -> ProbeLog:
    """liblsl-style probe bursts against a synthetic clock (host clock = true time).

    ``up_s`` and ``down_s`` are (fixed, mean exponential) one-way delays, s; unequal
    fixed parts make the exchange asymmetric.
    """
    rng = np.random.default_rng(seed)
    bursts = np.arange(0.0, duration_s, every_s)
    t0 = (bursts[:, None] + np.arange(burst)[None, :] * spacing_s).reshape(-1) + 0.25
    up = up_s[0] + rng.exponential(up_s[1], t0.shape)
    down = down_s[0] + rng.exponential(down_s[1], t0.shape)
    arrive = t0 + up
    leave = arrive + turnaround_s
    return ProbeLog(
        t0_s=t0, t1_ticks=clock.ticks(arrive), t2_ticks=clock.ticks(leave), t3_s=leave + down
    )
