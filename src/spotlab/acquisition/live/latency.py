"""Host latency per frame: a fixed histogram, constant memory for any run length."""

from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np

from spotlab.core.errors import ConfigurationError

__all__ = ["LatencyStats", "LatencySummary"]


@dataclass(frozen=True)
class LatencySummary:
    """Latency figures of one stream, in microseconds.

    Attributes
    ----------
    frames : int
        Frames measured.
    p50_us, p99_us : float
        Median and 99th percentile (resolution: the histogram's bin, 1 us by default;
        latencies beyond its range count as the range's end).
    max_us : float
        Largest latency, exact.
    mean_us : float
        Mean latency, exact.
    over_1ms : int
        Frames above 1 ms.
    """

    frames: int
    p50_us: float
    p99_us: float
    max_us: float
    mean_us: float
    over_1ms: int


class LatencyStats:
    """Histogram of per-frame latencies in ns (thread-safe).

    Parameters
    ----------
    bin_ns : int
        Bin width, ns (default 1000: 1 us).
    range_ns : int
        Upper end of the histogram, ns (default 50 ms); larger latencies land in the
        last bin (the exact maximum is kept apart).

    Raises
    ------
    ConfigurationError
        If ``bin_ns`` < 1 or ``range_ns`` < ``bin_ns``.
    """

    def __init__(self, bin_ns: int = 1000, range_ns: int = 50_000_000) -> None:
        if bin_ns < 1 or range_ns < bin_ns:
            raise ConfigurationError(f"bad latency histogram: bin {bin_ns} ns, range {range_ns} ns")
        self.bin_ns = int(bin_ns)
        self._last = range_ns // bin_ns
        self.counts = np.zeros(self._last + 1, dtype=np.int64)
        self.frames = 0
        self.max_ns = 0
        self.total_ns = 0
        self.over_1ms = 0
        self._lock = threading.Lock()

    def add(self, latency_ns: int) -> None:
        """Count one frame's latency (ns; negative values count as 0)."""
        ns = max(int(latency_ns), 0)
        with self._lock:
            self.counts[min(ns // self.bin_ns, self._last)] += 1
            self.frames += 1
            self.total_ns += ns
            if ns > self.max_ns:
                self.max_ns = ns
            if ns > 1_000_000:
                self.over_1ms += 1

    def percentile(self, q: float) -> float:
        """Latency below which a fraction ``q`` (0-100 %) of frames fall, us (NaN if none).

        The upper edge of the bin holding that frame, so never below the true value.
        """
        with self._lock:
            if not self.frames:
                return float("nan")
            rank = max(1, int(np.ceil(q / 100.0 * self.frames)))
            k = int(np.searchsorted(np.cumsum(self.counts), rank))
            return min((k + 1) * self.bin_ns, max(self.max_ns, 0)) / 1e3

    def summary(self) -> LatencySummary:
        """The figures so far."""
        n = self.frames
        return LatencySummary(
            frames=n,
            p50_us=self.percentile(50.0),
            p99_us=self.percentile(99.0),
            max_us=self.max_ns / 1e3 if n else float("nan"),
            mean_us=self.total_ns / n / 1e3 if n else float("nan"),
            over_1ms=self.over_1ms,
        )
