"""A synthetic ``image2d`` device for live-pipeline tests and benchmarks.

Larger than any SELSPOT-style system can be (128 LEDs in 100 us slots take 12.8 ms, so
at most 78 Hz): C cameras x M markers at any rate, all markers sampled at once (like
video cameras on a shared frame pulse). Frames are the projections of markers moving
on known paths (:meth:`SyntheticImage2d.truth`) through a rig, plus Gaussian noise.

The image coordinates of ``period`` frames are computed at :meth:`start` and repeat
(the device's work, which a real device does not do on the host): the paths are
periodic with ``period`` frames (:meth:`truth` folds ``seq`` the same way).

Pacing: frame ``k`` is due at ``t0 + k / rate`` on ``time.monotonic_ns``. ``recv``
waits until it is due, takes the arrival stamp then (the instant a real link would
have delivered the frame's last byte) and only then packs the :class:`FrameBlock`.
Several devices built with the same ``t0_ns`` take their frames at the same instants
with the same ticks: synchronised systems on one frame pulse. No wire bytes: taps see
only start and stop.
"""

from __future__ import annotations

import threading
import time
from typing import Any

import numpy as np
from numpy.typing import NDArray

from spotlab.acquisition.live.latency import LatencyStats
from spotlab.core.errors import DeviceError
from spotlab.core.frames import FrameBlock
from spotlab.core.stats import LinkStats
from spotlab.core.streams import StreamSpec
from spotlab.core.wire import WireTap
from spotlab.geometry import Rig

__all__ = ["SyntheticImage2d"]

FloatArray = NDArray[np.float64]
TICK_HZ = 1e6


class SyntheticImage2d:
    """Device of ``len(rig)`` cameras seeing ``n_markers`` moving markers.

    Parameters
    ----------
    rig : Rig
        Cameras (pixels as their image coordinates).
    n_markers : int
        Markers per frame.
    rate_hz : float
        Frame rate.
    name : str
        Stream name.
    noise_px : float
        Standard deviation of the image noise, px.
    seed : int
        Seeds the paths and the noise.
    t0_ns : int, optional
        Instant of frame 0 (``time.monotonic_ns``); default: at :meth:`start`.
    paced : bool
        Wait for each frame's instant (default); False: frames as fast as asked.
    paths_seed : int, optional
        Seed of the marker paths (default ``seed``): devices with the same paths seed
        and ``centre`` see the same markers.
    period : int
        Frames after which the motion repeats (default 600: 2 s at 300 Hz).
    centre : ndarray, shape (3,), optional
        Middle of the markers' volume, mm (default: in front of the rig's cameras,
        60 % of the way from their centroid to the first camera's distance).
    """

    def __init__(
        self,
        rig: Rig,
        n_markers: int,
        rate_hz: float,
        *,
        name: str = "synthetic",
        noise_px: float = 0.2,
        seed: int = 0,
        t0_ns: int | None = None,
        paced: bool = True,
        paths_seed: int | None = None,
        centre: FloatArray | None = None,
        period: int = 600,
    ) -> None:
        self.rig = rig
        self.name = name
        self.stats = LinkStats()
        self.rate_hz = float(rate_hz)
        self.noise_px = float(noise_px)
        self.paced = paced
        self._t0_fixed = t0_ns
        self.t0_ns = 0
        self._rng = np.random.default_rng(seed)
        paths = np.random.default_rng(seed if paths_seed is None else paths_seed)
        if centre is None:
            mean = np.mean([cam.center for cam in rig], axis=0)
            ahead = np.mean([cam.R[2] for cam in rig], axis=0)
            centre = mean + 0.6 * np.linalg.norm(rig.cameras[0].center - mean) * ahead
        self.centre = middle = np.asarray(centre, dtype=np.float64)
        self._base = middle + paths.uniform(-500.0, 500.0, (n_markers, 3))
        self._amp = paths.uniform(50.0, 200.0, (n_markers, 3))
        self._freq = paths.uniform(0.2, 2.0, (n_markers, 3))
        self._phase = paths.uniform(0.0, 2.0 * np.pi, (n_markers, 3))
        self._taps: list[WireTap] = []
        self._seq = 0
        self.period = int(period)
        self._frames: FloatArray | None = None
        self._stop = threading.Event()
        #: How late each frame was stamped after its due instant: the host reading
        #: behind the device (a real link's kernel buffer would hide it), ns.
        self.behind = LatencyStats()
        self._spec = StreamSpec(
            name=name,
            kind="image2d",
            n_sensors=len(rig),
            n_markers=n_markers,
            rate_hz=self.rate_hz,
            tick_hz=TICK_HZ,
            values=("x", "y"),
            units=("px", "px"),
            metadata={"family": "synthetic"},
        )

    @property
    def spec(self) -> StreamSpec:
        """Description of the stream."""
        return self._spec

    def truth(self, seq: int) -> FloatArray:
        """True marker positions of frame ``seq``, mm, shape (M, 3)."""
        t = (seq % self.period) / self.rate_hz
        return np.asarray(self._base + self._amp * np.sin(self._freq * t + self._phase))

    def _frame(self, seq: int) -> FloatArray:
        uv = self.rig.project(self.truth(seq))  # (C, M, 2)
        uv += self._rng.normal(0.0, self.noise_px, uv.shape)
        return np.ascontiguousarray(uv.transpose(1, 0, 2))  # (M, C, 2)

    def frames(self) -> FloatArray:
        """Image coordinates of the ``period`` frames the device repeats, px.

        Returns
        -------
        ndarray, shape (period, M, C, 2)
            Frame ``seq`` is row ``seq % period`` (computed on the first call).
        """
        if self._frames is None:
            self._frames = np.stack([self._frame(k) for k in range(self.period)])
        return self._frames

    def start(self) -> None:
        """Set frame 0's instant (unless given) and prepare it."""
        self._stop.clear()
        self.t0_ns = time.monotonic_ns() if self._t0_fixed is None else self._t0_fixed
        self._seq = 0
        self.frames()
        for tap in self._taps:
            tap.on_event(self.name, "started", {}, time.monotonic_ns())

    def stop(self) -> None:
        """Stop delivering frames."""
        self._stop.set()
        for tap in self._taps:
            tap.on_event(self.name, "stopped", {}, time.monotonic_ns())

    def close(self) -> None:
        """Same as :meth:`stop`."""
        self._stop.set()

    def add_tap(self, tap: WireTap) -> None:
        """Register a listener of link events (there are no wire bytes)."""
        self._taps.append(tap)

    def metadata(self) -> dict[str, Any]:
        """Family and stream description."""
        return {"family": "synthetic", "spec": self._spec.to_dict()}

    def recv(self, timeout: float | None = None) -> FrameBlock | None:
        """The next frame once it is due, or None after ``timeout`` seconds."""
        if self._stop.is_set():
            return None
        seq = self._seq
        if self._frames is None:
            raise DeviceError(f"{self.name}: recv before start")
        due = self.t0_ns + round(seq * 1e9 / self.rate_hz)
        if self.paced:
            wait_ns = due - time.monotonic_ns()
            if timeout is not None and wait_ns > timeout * 1e9:
                time.sleep(timeout)
                return None
            if wait_ns > 0:
                # A real link's read returns when the kernel wakes the reader: the stamp
                # is taken then, late by the wake-up (no spinning, which would hold the
                # GIL against the other readers of the session).
                time.sleep(wait_ns / 1e9)
        arrival = time.monotonic_ns()
        self.behind.add(arrival - due)
        data = self._frames[seq % self.period]
        block = FrameBlock(
            seq=np.array([seq], dtype=np.int64),
            ticks=np.array([round(seq * TICK_HZ / self.rate_hz)], dtype=np.int64),
            arrival_ns=np.array([arrival], dtype=np.int64),
            data=data[None],
            flags=np.ones(data.shape[:2], np.uint8)[None],
            status=np.zeros(1, np.uint16),
        )
        self._seq = seq + 1
        self.stats.frames += 1
        return block
