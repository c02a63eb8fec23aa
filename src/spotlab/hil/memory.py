"""The resident memory of a run's processes over time, for the soak's "memory stays flat".

While ``spotlab record`` runs, :class:`MemorySampler` reads the resident set size
(``VmRSS`` of ``/proc/PID/status``) of the recorder and of every simulator every
:func:`sample_interval` seconds. :func:`memory_figures` turns the recorder's samples
into the run's figures: its size once started (the first sample after
:data:`WARMUP_FRACTION` of the recording), at the end, and the growth between them.
"""

from __future__ import annotations

import csv
import threading
import time
from collections.abc import Mapping
from pathlib import Path

#: The share of the recording (at least :data:`WARMUP_MIN_S`) before the start figure.
WARMUP_FRACTION = 0.05
WARMUP_MIN_S = 2.0


def sample_interval(duration_s: float) -> float:
    """Seconds between samples: about 360 over the recording, 0.5 s at the most often."""
    return max(0.5, duration_s / 360.0)


def rss_mb(pid: int) -> float | None:
    """Resident set size of process ``pid`` in MB (10^6 bytes); None when it has ended."""
    try:
        with open(f"/proc/{pid}/status", encoding="ascii", errors="replace") as fh:
            for line in fh:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) * 1024 / 1e6  # kB
    except OSError:
        return None
    return None


class MemorySampler:
    """Samples the memory of named processes in a thread until :meth:`stop`.

    Parameters
    ----------
    pids : mapping
        Name -> process id (``record`` and the simulators' stream names).
    interval_s : float
        Seconds between samples.
    """

    def __init__(self, pids: Mapping[str, int], interval_s: float) -> None:
        self.pids = dict(pids)
        self.interval_s = interval_s
        #: (seconds since start, {name: MB or None}) per sample.
        self.samples: list[tuple[float, dict[str, float | None]]] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="hil-memory", daemon=True)
        self._t0 = time.monotonic()

    def start(self) -> MemorySampler:
        """Start sampling (one sample at once)."""
        self._t0 = time.monotonic()
        self._thread.start()
        return self

    def _run(self) -> None:
        while True:
            now = time.monotonic() - self._t0
            self.samples.append((now, {n: rss_mb(p) for n, p in self.pids.items()}))
            if self._stop.wait(self.interval_s):
                return

    def stop(self) -> None:
        """Stop sampling and wait for the thread."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=5.0)

    def write_csv(self, path: Path) -> Path:
        """``t_s`` and one column of MB per process."""
        names = list(self.pids)
        with open(path, "w", newline="", encoding="utf-8") as fh:
            out = csv.writer(fh)
            out.writerow(["t_s", *(f"{n}_rss_mb" for n in names)])
            for t, row in self.samples:
                values = [row.get(n) for n in names]
                out.writerow([f"{t:.2f}", *("" if v is None else f"{v:.2f}" for v in values)])
        return path


def memory_figures(
    samples: list[tuple[float, dict[str, float | None]]], duration_s: float, name: str = "record"
) -> dict[str, float | None]:
    """The recorder's memory once started, at the end and the growth, in MB.

    ``record_rss_start_mb`` is the first sample after the warm-up (:data:`WARMUP_FRACTION`
    of ``duration_s``, at least :data:`WARMUP_MIN_S`), ``record_rss_end_mb`` the last
    sample within ``duration_s`` of the recorder's start (not its summary of the journal
    after it), ``record_rss_growth_mb`` the end less the start, and
    ``record_rss_peak_mb`` the largest sample within it. None when there are no such
    samples.
    """
    live = [(t, row[name]) for t, row in samples if row.get(name) is not None and t <= duration_s]
    warm = max(WARMUP_MIN_S, WARMUP_FRACTION * duration_s)
    after = [(t, v) for t, v in live if t >= warm]
    out: dict[str, float | None] = dict.fromkeys(
        ("record_rss_start_mb", "record_rss_end_mb", "record_rss_growth_mb", "record_rss_peak_mb")
    )
    if not after:
        return out
    start, end = float(after[0][1] or 0.0), float(after[-1][1] or 0.0)
    out.update(
        record_rss_start_mb=round(start, 2),
        record_rss_end_mb=round(end, 2),
        record_rss_growth_mb=round(end - start, 2),
        record_rss_peak_mb=round(max(float(v or 0.0) for _, v in live), 2),
    )
    return out


__all__ = ["MemorySampler", "memory_figures", "rss_mb", "sample_interval"]
