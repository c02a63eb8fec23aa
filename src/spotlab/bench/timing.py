"""Timing figures of one stream from per-frame stamps (pure functions, no I/O).

A frame has a device time (its ``ticks`` over the stream's tick rate), a host
arrival stamp (``arrival_ns``: the read that brought its last byte returned) and a
delivery stamp (the bench's sink saw it). From these:

* the device clock against the host: the straight line under every arrival
  (against device time) that is closest to them on average, an edge of their
  lower convex hull (the late arrivals are the host's delays, not the clock's:
  every residual is at or above the line). Its slope gives the
  drift (ppm, positive when the device clock runs slow against the host's), its
  value at the first frame the offset
  (host time minus device time there, which includes the transport's latency);
* frame-arrival jitter: each arrival's delay above that line (its standard
  deviation, its 99th percentile, peak to peak), in µs;
* host latency per frame: delivery minus arrival, p50 / p99 / max in µs;
* the measured frame rate and, where the line has a known capacity, the share
  of it the stream's bytes used.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

I64 = npt.NDArray[np.int64]


@dataclass(frozen=True)
class FrameStamps:
    """Stamps of the frames of one stream, in arrival order.

    Attributes
    ----------
    ticks : ndarray of int64, shape (n,)
        Device time stamps (unwrapped), in device ticks.
    tick_hz : float
        Device ticks per second.
    arrival_ns : ndarray of int64, shape (n,)
        Host monotonic time the frame's last byte was read, ns.
    delivered_ns : ndarray of int64, shape (n,)
        Host monotonic time the bench's sink received the frame, ns.
    """

    ticks: I64
    tick_hz: float
    arrival_ns: I64
    delivered_ns: I64

    def __len__(self) -> int:
        return int(self.ticks.shape[0])


def percentiles_us(values_ns: npt.NDArray[np.int64]) -> dict[str, float | None]:
    """``p50_us``, ``p99_us``, ``max_us`` of ``values_ns`` (None for no values)."""
    if values_ns.shape[0] == 0:
        return {"p50_us": None, "p99_us": None, "max_us": None}
    p50, p99 = np.percentile(values_ns.astype(np.float64), [50.0, 99.0]) / 1e3
    return {
        "p50_us": round(float(p50), 1),
        "p99_us": round(float(p99), 1),
        "max_us": round(float(values_ns.max()) / 1e3, 1),
    }


def clock_fit(stamps: FrameStamps) -> tuple[float, float, npt.NDArray[np.float64]]:
    """Arrival time against device time, fitted by a straight line.

    Returns
    -------
    drift_ppm : float
        ``(slope - 1) * 1e6``: host seconds per device second, less one, in ppm.
    offset_s : float
        Host time minus device time at the first frame (fitted), s.
    residual_ns : ndarray of float64, shape (n,)
        Each arrival minus the line, ns.
    """
    if len(stamps) < 3:
        return float("nan"), float("nan"), np.zeros(len(stamps))
    device_s = (stamps.ticks - stamps.ticks[0]).astype(np.float64) / stamps.tick_hz
    host_s = (stamps.arrival_ns - stamps.arrival_ns[0]).astype(np.float64) / 1e9
    slope, intercept = _lower_support(device_s, host_s)
    residual = (host_s - (slope * device_s + intercept)) * 1e9
    offset = (
        float(stamps.arrival_ns[0]) / 1e9
        + float(intercept)
        - float(stamps.ticks[0]) / (stamps.tick_hz)
    )
    return (float(slope) - 1.0) * 1e6, offset, residual


def _lower_support(x: npt.NDArray[np.float64], y: npt.NDArray[np.float64]) -> tuple[float, float]:
    """The line under every point ``(x, y)`` closest to them on average.

    It is the edge of the points' lower convex hull above their mean ``x`` (the
    solution of: maximise the line's mean height subject to staying under every
    point), the host's least-delayed arrivals.
    """
    order = np.lexsort((y, x))
    hull: list[int] = []
    for i in order.tolist():
        while len(hull) >= 2:
            a, b = hull[-2], hull[-1]
            cross = (x[b] - x[a]) * (y[i] - y[a]) - (y[b] - y[a]) * (x[i] - x[a])
            if cross > 0:
                break
            hull.pop()
        hull.append(i)
    mean = float(np.mean(x))
    for a, b in itertools.pairwise(hull):
        if x[a] <= mean <= x[b] and x[b] > x[a]:
            slope = float((y[b] - y[a]) / (x[b] - x[a]))
            return slope, float(y[a] - slope * x[a])
    slope, intercept = np.polyfit(x, y, 1)
    return float(slope), float(intercept)


def stream_figures(
    stamps: FrameStamps,
    seconds: float,
    nominal_rate_hz: float,
    data_bytes: int,
    line_bits_per_s: float | None,
) -> dict[str, float | int | None]:
    """The bench's timing figures of one stream.

    Parameters
    ----------
    stamps : FrameStamps
        The frames measured.
    seconds : float
        How long the stream was measured, s.
    nominal_rate_hz : float
        The frame rate the device was set to, Hz.
    data_bytes : int
        Bytes read from the line while measuring.
    line_bits_per_s : float or None
        The line's capacity (10 bit times per byte at the baud rate); None when the
        transport has no fixed capacity (TCP).

    Returns
    -------
    dict
        ``frames``, ``rate_hz``, ``nominal_rate_hz``, ``jitter_rms_us``,
        ``jitter_p99_us``, ``jitter_pp_us``, ``latency_p50_us``, ``latency_p99_us``,
        ``latency_max_us``, ``throughput_bits_per_s``, ``line_bits_per_s``,
        ``line_use``, ``clock_drift_ppm``, ``clock_offset_ms``.
    """
    n = len(stamps)
    drift, offset, residual = clock_fit(stamps)
    latency = percentiles_us(stamps.delivered_ns - stamps.arrival_ns)
    span_s = float(stamps.arrival_ns[-1] - stamps.arrival_ns[0]) / 1e9 if n > 1 else 0.0
    rate = (n - 1) / span_s if span_s > 0 else 0.0
    bits = data_bytes * 10.0 / seconds if seconds > 0 else 0.0
    out: dict[str, float | int | None] = {
        "frames": n,
        "rate_hz": round(rate, 3),
        "nominal_rate_hz": nominal_rate_hz,
        "jitter_rms_us": _round(float(np.std(residual)) / 1e3 if n >= 3 else None),
        "jitter_p99_us": _round(
            float(np.percentile(np.abs(residual), 99.0)) / 1e3 if n >= 3 else None
        ),
        "jitter_pp_us": _round(float(np.ptp(residual)) / 1e3 if n >= 3 else None),
        "latency_p50_us": latency["p50_us"],
        "latency_p99_us": latency["p99_us"],
        "latency_max_us": latency["max_us"],
        "throughput_bits_per_s": round(bits, 1),
        "line_bits_per_s": line_bits_per_s,
        "line_use": round(bits / line_bits_per_s, 4) if line_bits_per_s else None,
        "clock_drift_ppm": _round(drift if np.isfinite(drift) else None, 2),
        "clock_offset_ms": _round(offset * 1e3 if np.isfinite(offset) else None, 3),
    }
    return out


def _round(value: float | None, digits: int = 1) -> float | None:
    return None if value is None else round(value, digits)


__all__ = ["FrameStamps", "clock_fit", "percentiles_us", "stream_figures"]
