"""Timing figures of one stream from per-frame stamps (pure functions, no I/O).

A frame has a device time (its ``ticks`` over the stream's tick rate), a host
arrival stamp (``arrival_ns``: the read that brought its last byte returned) and a
delivery stamp (the bench's sink saw it). From these:

* the device clock against the host: a straight line fitted to arrival time
  against device time through the lower envelope of the arrivals (the earliest
  of each of 20 spans: the late ones are the host's delays, not the clock's;
  the residuals are then all at or above the line). Its slope gives the
  drift (ppm, positive when the device clock runs slow against the host's), its
  value at the first frame the offset
  (host time minus device time there, which includes the transport's latency);
* frame-arrival jitter: what is left of the arrivals around that line (RMS, p99
  of the absolute residual, peak to peak), in µs;
* host latency per frame: delivery minus arrival, p50 / p99 / max in µs;
* the measured frame rate and, where the line has a known capacity, the share
  of it the stream's bytes used.
"""

from __future__ import annotations

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
    # The lower envelope: in each of about 20 spans of device time the earliest arrival
    # (against the device clock) is the one the host delayed least; the line through
    # them is the clock, the rest of each arrival is the host's delay.
    spans = np.minimum((device_s / max(device_s[-1], 1e-9) * 20).astype(np.int64), 19)
    lag = host_s - device_s
    picks = [int(np.flatnonzero(spans == k)[np.argmin(lag[spans == k])])
             for k in np.unique(spans)]  # fmt: skip
    if len(picks) >= 3:
        slope, intercept = np.polyfit(device_s[picks], host_s[picks], 1)
    else:
        slope, intercept = np.polyfit(device_s, host_s, 1)
    residual = (host_s - (slope * device_s + intercept)) * 1e9
    offset = (
        float(stamps.arrival_ns[0]) / 1e9
        + float(intercept)
        - float(stamps.ticks[0]) / (stamps.tick_hz)
    )
    return (float(slope) - 1.0) * 1e6, offset, residual


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
        "jitter_rms_us": _round(float(np.sqrt(np.mean(residual**2))) / 1e3 if n >= 3 else None),
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
