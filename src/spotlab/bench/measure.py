"""Stream devices for a while and take the stamps the bench's figures are made of.

The drivers run in a :class:`~spotlab.acquisition.session.Session`, as ``spotlab
record`` runs them; a sink stamps every block with the host's monotonic clock when
it is delivered (the session's reader, its queue and the hand-off to the sink's
thread are in the latency; the kernel and the transport before the read are not).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from spotlab.acquisition.session import Session, SinkBase
from spotlab.bench.timing import FrameStamps, stream_figures
from spotlab.core.frames import FrameBlock
from spotlab.drivers.base import Driver


class StampSink(SinkBase):
    """Keeps ``ticks``, ``arrival_ns`` and the delivery time of every frame, per stream."""

    name = "bench"

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self.ticks: dict[str, list[np.ndarray]] = {}
        self.arrival: dict[str, list[np.ndarray]] = {}
        self.delivered: dict[str, list[np.ndarray]] = {}

    def on_block(self, stream: str, block: FrameBlock) -> None:
        now = time.monotonic_ns()
        if not len(block):
            return
        with self._lock:
            self.ticks.setdefault(stream, []).append(np.asarray(block.ticks, dtype=np.int64))
            self.arrival.setdefault(stream, []).append(np.asarray(block.arrival_ns, dtype=np.int64))
            self.delivered.setdefault(stream, []).append(np.full(len(block), now, np.int64))

    def stamps(self, stream: str, tick_hz: float) -> FrameStamps:
        """The stamps of ``stream`` (empty arrays when it delivered nothing)."""

        def cat(parts: dict[str, list[np.ndarray]]) -> np.ndarray:
            got = parts.get(stream, [])
            return np.concatenate(got) if got else np.zeros(0, np.int64)

        with self._lock:
            return FrameStamps(cat(self.ticks), tick_hz, cat(self.arrival), cat(self.delivered))


@dataclass
class StreamResult:
    """What one device did while measured.

    Attributes
    ----------
    stream : str
        Stream name.
    figures : dict
        :func:`~spotlab.bench.timing.stream_figures` plus the link counters
        (``lost_frames``, ``crc_errors``, ``resyncs``, ``duplicates``, ``reconnects``).
    stamps : FrameStamps
        The frames, for the plots.
    errors : list of str
        Errors the device raised while streaming.
    """

    stream: str
    figures: dict[str, Any]
    stamps: FrameStamps
    errors: list[str] = field(default_factory=list)


def line_capacity(driver: Driver) -> float | None:
    """Bits per second the driver's line carries (10 bit times a byte), if it has a baud."""
    config = getattr(driver, "config", None)
    baud = getattr(config, "baud", None)
    return float(baud) * 1.0 if isinstance(baud, int) and baud > 0 else None


#: Seconds of frames left out at the start (a backlog read in a burst, a first read).
WARMUP_S = 0.5


def _after_warmup(stamps: FrameStamps) -> FrameStamps:
    """The frames that arrived :data:`WARMUP_S` or more after the first."""
    if len(stamps) == 0:
        return stamps
    keep = stamps.arrival_ns >= stamps.arrival_ns[0] + int(WARMUP_S * 1e9)
    return FrameStamps(
        stamps.ticks[keep], stamps.tick_hz, stamps.arrival_ns[keep], stamps.delivered_ns[keep]
    )


COUNTERS = ("lost_frames", "crc_errors", "resyncs", "duplicates", "reconnects")


def measure(drivers: Sequence[Driver], seconds: float) -> list[StreamResult]:
    """Stream ``drivers`` together for ``seconds`` (after :data:`WARMUP_S` not measured)
    and return their figures; the throughput counts every byte of the run.

    The drivers are started and closed here.
    """
    sink = StampSink()
    session = Session(list(drivers), [sink], close_devices=True)
    session.run_for(seconds + WARMUP_S)
    results = []
    for driver in drivers:
        spec = driver.spec
        stamps = _after_warmup(sink.stamps(driver.name, float(spec.tick_hz)))
        figures: dict[str, Any] = stream_figures(
            stamps, seconds + WARMUP_S, float(spec.rate_hz), driver.stats.bytes,
            line_capacity(driver),
        )  # fmt: skip
        for key in COUNTERS:
            figures[key] = int(getattr(driver.stats, key))
        errors = [str(e.error) for e in session.errors if e.stream == driver.name]
        results.append(StreamResult(driver.name, figures, stamps, errors))
    return results


__all__ = ["COUNTERS", "StampSink", "StreamResult", "line_capacity", "measure"]
