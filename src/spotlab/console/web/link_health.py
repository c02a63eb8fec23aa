"""Link health over time: each device's frames, lost frames and CRC errors per second.

A daemon thread reads the device rows (:meth:`Acquisition.devices`, the drivers'
counters of the running session) once a second and keeps the increase of each counter
over the last :data:`WINDOW` seconds. A counter that went down (a new session: new
driver objects counting from zero) counts from zero again. It reads counters only; the
acquisition never waits for it.
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Any

__all__ = ["COUNTERS", "WINDOW", "LinkHealth"]

#: Seconds of history kept.
WINDOW = 60
#: Device-row counters followed (API name -> row key).
COUNTERS = {"frames": "frames", "lost": "lost_frames", "crc": "crc_errors"}


class LinkHealth:
    """Per-second increases of the devices' counters, the last :data:`WINDOW` seconds.

    Parameters
    ----------
    rows : callable
        Returns the device rows (dicts with ``name`` and the :data:`COUNTERS` keys).
    period_s : float
        Sampling period, s.
    """

    def __init__(self, rows: Callable[[], list[dict[str, Any]]], period_s: float = 1.0):
        self.rows, self.period_s = rows, period_s
        self._lock = threading.Lock()
        self._last: dict[str, dict[str, int]] = {}
        self._history: dict[str, deque[dict[str, float]]] = {}
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self) -> None:
        """Start sampling in a daemon thread."""
        self._thread = threading.Thread(target=self._run, name="console-health", daemon=True)
        self._thread.start()

    def close(self) -> None:
        """Stop sampling."""
        self._stop.set()

    def sample(self, now: float | None = None) -> None:
        """Read the rows once and append each device's increases since the last read."""
        t = time.time() if now is None else now
        rows = self.rows()
        with self._lock:
            for row in rows:
                name = str(row["name"])
                counts = {k: int(row.get(key) or 0) for k, key in COUNTERS.items()}
                last = self._last.get(name)
                self._last[name] = counts
                if last is None:
                    continue  # the first read is the baseline
                step: dict[str, float] = {"t": round(t, 3)}
                for k, v in counts.items():
                    step[k] = v - last[k] if v >= last[k] else v  # a new session: from 0
                self._history.setdefault(name, deque(maxlen=WINDOW)).append(step)

    def snapshot(self) -> dict[str, Any]:
        """JSON-safe: ``period_s`` and per device ``t`` (epoch s) and per-period
        ``frames``, ``lost``, ``crc``, oldest first."""
        with self._lock:
            devices = {
                name: {key: [s[key] for s in steps] for key in ("t", *COUNTERS)}
                for name, steps in self._history.items()
            }
        return {"period_s": self.period_s, "window_s": WINDOW, "devices": devices}

    def _run(self) -> None:
        due = time.monotonic()
        while not self._stop.is_set():
            # a row being rebuilt raises: the next period reads again
            with contextlib.suppress(Exception):
                self.sample()
            due = max(due + self.period_s, time.monotonic() - self.period_s)
            self._stop.wait(max(0.0, due - time.monotonic()))
