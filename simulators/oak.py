"""A fake OAK board: renders a scene's markers into mono frames and replays them.

It stands behind the OAK driver's seam (``spotlab.drivers.oak.seam.OakCamera``)
the way a real board does, with frames stamped on a clock of its own: the whole
driver (centroiding, matching, timestamps, journal) runs without hardware. Written
from the seam's description (docs/oak.md), not from the driver.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from spotlab.core.errors import DeviceError
from spotlab.geometry import Camera, Rig
from spotlab.imaging import render_blobs
from spotlab.simulators.clock import DeviceClock
from spotlab.simulators.motions import Motion
from spotlab.simulators.rigs import ring_rig

__all__ = ["FakeFrame", "FakeOakDevice", "oak_rig"]

F64 = npt.NDArray[np.float64]


def oak_rig(n_cameras: int = 4, seed: int = 0) -> Rig:
    """The reference ring of TARGETS.md with OAK mono sensors: 1280x800 px images."""
    return ring_rig(n_cameras, size=(1280, 800), seed=seed)


@dataclass(frozen=True)
class FakeFrame:
    """One rendered image with its times (the fields a real board's frame has)."""

    socket: str
    seq: int
    image: npt.NDArray[np.uint8]
    host_ns: int
    device_ns: int
    exposure_us: int


class FakeOakDevice:
    """One fake OAK board with one mono camera per ``Camera`` of the scene.

    Frame ``k`` is exposed around ``start + k / fps`` (host clock); its marker
    positions are the motion's at that instant. Each call of :meth:`frames` returns
    the next frame of every camera (no pacing: tests run as fast as the host). Like a
    running depthai pipeline it refuses a second :meth:`start`; :meth:`stop` lets a
    new run begin (frames count from 0 again). ``info`` says what a real board would
    report (USB ``SUPER``; the first images' format and FSIN mode).

    Parameters
    ----------
    mxid : str
        The board's id.
    cameras : sequence of Camera
        One per socket; their image sizes must equal the requested size.
    motion : Motion
        Marker trajectories (mm).
    sockets : sequence of str, optional
        Socket names (default ``CAM_B``, ``CAM_C``, ...).
    n_frames : int, optional
        Frames before the board falls silent (default unlimited).
    marker_mm : float
        Marker diameter (mm); its image diameter is ``fx * marker_mm / depth``.
    peak, background, noise : float
        Blob plateau, dark level and read noise (counts).
    clock : DeviceClock, optional
        The board's clock (device timestamps); default offset 12.5 s, drift 30 ppm.
    dropouts : dict, optional
        ``socket -> (first, stop)``: that camera delivers no image for frames
        ``first <= k < stop`` (a cable that comes and goes).
    open_error : Exception, optional
        Raised by :meth:`open` (a board that is missing or not permitted).
    seed : int
        Noise seed.
    """

    def __init__(
        self,
        mxid: str,
        cameras: Sequence[Camera],
        motion: Motion,
        *,
        sockets: Sequence[str] | None = None,
        n_frames: int | None = None,
        marker_mm: float = 14.0,
        peak: float = 200.0,
        background: float = 6.0,
        noise: float = 0.0,
        clock: DeviceClock | None = None,
        dropouts: dict[str, tuple[int, int]] | None = None,
        open_error: Exception | None = None,
        seed: int = 0,
    ) -> None:
        self.mxid = mxid
        self.camera_models = list(cameras)
        names = sockets or [f"CAM_{chr(ord('B') + i)}" for i in range(len(self.camera_models))]
        self.sockets = tuple(names)
        if len(self.sockets) != len(self.camera_models):
            raise DeviceError("a fake OAK needs one socket name per camera")
        self.motion = motion
        self.n_frames = n_frames
        self.marker_mm, self.peak = marker_mm, peak
        self.background, self.noise = background, noise
        self.clock = clock or DeviceClock(offset_s=12.5, drift_ppm=30.0)
        self.dropouts = dict(dropouts or {})
        self.open_error = open_error
        self.rng = np.random.default_rng(seed)
        self.settings: Any = None
        self.opened = self.started = self.closed = False
        #: What the board reported at start (a real board: USB speed, sensors).
        self.info: dict[str, str] = {}
        self.starts = 0
        self._k = 0
        self._start_ns = 0

    # -- the seam ----------------------------------------------------------------------
    def open(self, settings: Any) -> None:
        """Accept the settings (checked against the cameras' image size)."""
        if self.open_error is not None:
            raise self.open_error
        for cam in self.camera_models:
            if tuple(settings.size) != cam.size:
                raise DeviceError(f"fake OAK {self.mxid}: size {settings.size} != {cam.size}")
        self.settings = settings
        self.opened = True

    def start(self) -> None:
        """Start the virtual exposure clock now."""
        if not self.opened:
            raise DeviceError(f"fake OAK {self.mxid}: open() before start()")
        if self.started:
            raise DeviceError(f"fake OAK {self.mxid}: the pipeline is already running")
        self._start_ns = time.monotonic_ns()
        self._k = 0
        self.started = True
        self.starts += 1
        self.info = {"usb_speed": "SUPER"}

    def stop(self) -> None:
        """Stop streaming; :meth:`start` may follow (frames count from 0 again)."""
        self.started = False

    def frames(self, timeout: float) -> list[FakeFrame]:
        """The next frame of every camera; none once ``n_frames`` are out."""
        if not self.started:
            raise DeviceError(f"fake OAK {self.mxid} is not streaming")
        if self.n_frames is not None and self._k >= self.n_frames:
            time.sleep(min(timeout, 0.01))
            return []
        k = self._k
        self._k += 1
        if k == 0:
            self._report_first()
        host_ns = self.exposure_mid_ns(k)
        device_ns = round(self.clock.device_us(host_ns) * 1000)
        out = []
        for socket, cam, uv in zip(self.sockets, self.camera_models, self.truth_uv(k), strict=True):
            first, stop = self.dropouts.get(socket, (0, 0))
            if first <= k < stop:
                continue
            depth = self._depth(cam, k)
            image = render_blobs(
                cam.size, uv, cam.K[0, 0] * self.marker_mm / depth, peak=self.peak,
                background=self.background, noise=self.noise, rng=self.rng,
            )  # fmt: skip
            out.append(
                FakeFrame(
                    socket,
                    k,
                    image.astype(np.uint8, copy=False),
                    host_ns,
                    device_ns,
                    int(self.settings.exposure_us),
                )
            )
        return out

    def _report_first(self) -> None:
        """What a real board's first images say: GRAY8 at the asked size, and the FSIN
        mode the sensor ran in (master: first socket drives, the others follow)."""
        w, h = self.settings.size
        for i, socket in enumerate(self.sockets):
            self.info[f"format.{socket}"] = f"GRAY8 {w}x{h}"
            sync = self.settings.sync
            mode = {"master": "OUTPUT" if i == 0 else "INPUT", "slave": "INPUT"}.get(sync, "NONE")
            self.info[f"fsync.{socket}"] = mode

    def close(self) -> None:
        """Stop; safe twice."""
        self.started = False
        self.closed = True

    # -- ground truth ------------------------------------------------------------------
    def exposure_mid_ns(self, k: int) -> int:
        """Host time (ns) of frame ``k``'s exposure mid-point."""
        return self._start_ns + round(k * 1e9 / float(self.settings.fps))

    def truth_uv(self, k: int) -> F64:
        """True image positions of every marker in frame ``k``, shape (C, M, 2) px, NaN
        where a marker is behind a camera or outside its image."""
        X = self.motion.positions((self.exposure_mid_ns(k) - self._start_ns) / 1e9)
        out = np.full((len(self.camera_models), X.shape[0], 2), np.nan)
        for c, cam in enumerate(self.camera_models):
            uv = cam.project(X)
            w, h = cam.size
            inside = (uv[:, 0] >= 0) & (uv[:, 0] <= w - 1) & (uv[:, 1] >= 0) & (uv[:, 1] <= h - 1)
            inside &= (X @ cam.R.T + cam.t)[:, 2] > 0
            out[c, inside] = uv[inside]
        return out

    def _depth(self, cam: Camera, k: int) -> F64:
        X = self.motion.positions((self.exposure_mid_ns(k) - self._start_ns) / 1e9)
        return np.maximum((X @ cam.R.T + cam.t)[:, 2], 1.0)
