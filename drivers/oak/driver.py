"""OAK boards as one video-centroid stream: host-side centroids, frames matched by exposure time."""

from __future__ import annotations

import os
import time
from collections import deque
from collections.abc import Sequence
from dataclasses import asdict, replace
from typing import Any

from spotlab.core.errors import ConfigurationError, DeviceDisconnected, DeviceError
from spotlab.core.frames import FrameBlock
from spotlab.core.streams import StreamSpec
from spotlab.drivers.base import DeviceInfo, Driver
from spotlab.drivers.oak.record import MAGIC, CameraShot, OakRecordDecoder, encode_frame
from spotlab.drivers.oak.record import stream_spec as _stream_spec
from spotlab.drivers.oak.seam import CameraSettings, OakCamera, OakFrameLike
from spotlab.imaging import find_blobs

#: A camera whose frames lag the others by this many periods is declared offline
#: for the frames it missed, so one dead camera never stalls the stream.
MAX_WAIT_PERIODS = 3
#: With several boards, the wait for the first frame polls them in turn this often (s).
POLL_S = 0.002


class OakDriver(Driver):
    """One or more OAK boards, FSIN-synced, as one ``blobs2d`` stream.

    Each mono image is thresholded and centroided on the host
    (:func:`spotlab.imaging.find_blobs`); the images of one trigger are matched across
    cameras and boards by their host-synced exposure mid-points (within half a
    period) and delivered as one frame: ``data[f, k, c] = (x, y, area, peak, dt)`` for
    blob ``k`` of camera ``c``, NaN past its last blob; ``ticks`` the exposure
    mid-point of the lowest-numbered camera that delivered, on the host monotonic
    clock (ns); ``dt`` each camera's mid-point minus ``ticks`` (s). A camera without
    an image for a frame is flagged offline there (docs/oak.md).

    Parameters
    ----------
    port : str
        MxIds of the boards, comma-separated; the first drives FSIN (``master``), the
        others follow (``slave``). One board runs free unless ``settings.sync`` says.
    name : str, optional
        Stream name (default ``"oak"``).
    boards : sequence of OakCamera, optional
        The boards behind the seam; default a ``DepthaiCamera`` per MxId. Tests pass
        fakes (``spotlab.simulators.oak.FakeOakDevice``).
    settings : CameraSettings, optional
        Image size, rate, exposure and ISO of every camera.
    threshold : float
        Grey level above which pixels belong to blobs.
    min_area, max_area, min_peak, max_blobs
        Gates of :func:`~spotlab.imaging.find_blobs`; ``max_blobs`` is also the
        stream's marker axis.
    """

    family = "oak"

    def __init__(
        self,
        port: str | os.PathLike[str],
        *,
        name: str | None = None,
        boards: Sequence[OakCamera] | None = None,
        settings: CameraSettings | None = None,
        threshold: float = 60.0,
        min_area: int = 2,
        max_area: int | None = 400,
        min_peak: float = 0.0,
        max_blobs: int = 64,
    ) -> None:
        super().__init__(port, name=name)
        mxids = [m for m in self.port.split(",") if m]
        if boards is None:
            from spotlab.drivers.oak.depthai_camera import DepthaiCamera

            boards = [DepthaiCamera(m) for m in mxids]
        if not boards:
            raise ConfigurationError("an OAK driver needs at least one board MxId")
        self.boards = list(boards)
        self.settings = settings or CameraSettings()
        self.gates: dict[str, Any] = {
            "threshold": float(threshold), "min_area": min_area, "max_area": max_area,
            "min_peak": float(min_peak), "max_blobs": max_blobs,
        }  # fmt: skip
        self.cameras = [(b.mxid, s) for b in self.boards for s in b.sockets]
        self._index = {cam: i for i, cam in enumerate(self.cameras)}
        self._spec = _stream_spec(
            self.name, len(self.cameras), max_blobs, self.settings.fps,
            camera_names=[f"{m}/{s}" for m, s in self.cameras],
        )  # fmt: skip
        self._decoder = OakRecordDecoder(self._spec, self.stats)
        self._pending: list[deque[CameraShot]] = [deque() for _ in self.cameras]
        self._seq = 0
        self._open = False

    @property
    def spec(self) -> StreamSpec:
        """The ``blobs2d`` stream: cameras x ``max_blobs`` x (x, y, area, peak, dt)."""
        return self._spec

    def metadata(self) -> dict[str, Any]:
        """Spec, boards, camera settings, centroid gates and the journal layout."""
        return {
            **super().metadata(),
            "boards": [
                {"mxid": b.mxid, "sockets": list(b.sockets), "reported": dict(b.info)}
                for b in self.boards
            ],
            "settings": asdict(self.settings),
            "centroid": dict(self.gates),
            "layout": MAGIC.decode(),
            "decoder": "spotlab.drivers.oak:decoder_from_metadata",
        }

    @classmethod
    def detect(cls) -> list[DeviceInfo]:
        """OAK boards on the bus, the ones this user may not open included (none when
        depthai is not installed). A board without permission has no MxId yet: its
        port is empty and its description says to install the udev rule."""
        try:
            from spotlab.drivers.oak.depthai_camera import PERMISSION, find_devices

            found = find_devices()
        except ConfigurationError:
            return []
        out = []
        for mxid, usb, state, status in found:
            what = f"OAK at USB {usb} ({state}, {status})"
            if status == PERMISSION:
                what += ": no permission, run `spotlab udev install`"
            out.append(DeviceInfo("oak", mxid, what, mxid, {"usb": usb, "state": state}))
        return out

    # -- life cycle ------------------------------------------------------------------
    def _start(self) -> None:
        if not self._open:
            many = len(self.boards) > 1
            for i, board in enumerate(self.boards):
                sync = self.settings.sync
                if many:
                    sync = "master" if i == 0 else "slave"
                settings = replace(self.settings, sync=sync)
                try:
                    board.open(settings)
                except BaseException:
                    self._close()
                    raise
                self._tap_event("open", port=board.mxid, sync=sync)
            self._open = True
        started: list[OakCamera] = []
        try:
            for board in self.boards:
                board.start()
                started.append(board)
                self._tap_event("configured", port=board.mxid, **board.info)
        except BaseException:
            for board in started:
                board.stop()
            raise
        self._tap_event("started")

    def _stop(self) -> None:
        try:
            for board in self.boards:
                board.stop()
        finally:
            # Images of a stopped run never match the next run's: drop them.
            self._pending = [deque() for _ in self.cameras]
            self._tap_event("stopped")

    def _close(self) -> None:
        for board in self.boards:
            board.close()
        if self._open:
            self._tap_event("close", port=self.port)
        self._open = False

    # -- streaming -------------------------------------------------------------------
    def _recv_internal(self, timeout: float | None) -> FrameBlock | None:
        if not self._started and not self._open:
            raise DeviceError(f"{self.name} ({self.port}) is not streaming: call start() first")
        wait = 1.0 if timeout is None else timeout
        try:
            for mxid, frame in self._read(wait):
                self._ingest(mxid, frame)
        except DeviceDisconnected as exc:
            self._tap_event("disconnected", port=self.port, error=str(exc))
            raise
        records = b"".join(encode_frame(self._next_seq(), shots) for shots in self._matched())
        if not records:
            return None
        arrival_ns = time.monotonic_ns()
        self.stats.bytes += len(records)
        self._tap_rx(records, arrival_ns)
        return self._decoder.feed(records, arrival_ns)

    def _read(self, wait: float) -> list[tuple[str, OakFrameLike]]:
        """Frames of every board, waiting up to ``wait`` s for the first on any of them.

        One board waits in depthai on all its queues at once; several are polled in
        turn in slices of :data:`POLL_S`, so a dead board never delays the others by
        more than a slice.
        """
        deadline = time.monotonic() + wait
        while True:
            got = []
            for board in self.boards:
                step = wait if len(self.boards) == 1 else 0.0
                got += [(board.mxid, f) for f in board.frames(step)]
            left = deadline - time.monotonic()
            if got or left <= 0 or len(self.boards) == 1:
                return got
            time.sleep(min(POLL_S, left))

    def _next_seq(self) -> int:
        self._seq += 1
        return self._seq - 1

    def _ingest(self, mxid: str, frame: OakFrameLike) -> None:
        cam = self._index.get((mxid, frame.socket))
        if cam is None:
            return
        g = self.gates
        blobs = find_blobs(
            frame.image, g["threshold"], min_area=g["min_area"], max_area=g["max_area"],
            min_peak=g["min_peak"], max_blobs=g["max_blobs"],
        )  # fmt: skip
        self._pending[cam].append(
            CameraShot(cam, blobs, frame.seq, frame.exposure_us, frame.host_ns, frame.device_ns)
        )

    def _matched(self) -> list[list[CameraShot]]:
        """Frames complete in every camera, or given up on for the cameras that lag."""
        period_ns = 1e9 / self.settings.fps
        out: list[list[CameraShot]] = []
        while any(self._pending):
            heads = [q[0].host_ns for q in self._pending if q]
            newest = max(q[-1].host_ns for q in self._pending if q)
            t0 = min(heads)
            if not all(self._pending) and newest - t0 < MAX_WAIT_PERIODS * period_ns:
                break
            shots = []
            for cam, q in enumerate(self._pending):
                if q and q[0].host_ns - t0 < period_ns / 2:
                    shots.append(q.popleft())
                else:
                    shots.append(CameraShot(cam, None))
            out.append(shots)
        return out
