"""Byte-level emulator of the CEN video-centroid hub (docs/protocols/centroid.md).

:class:`CentroidDevice` is an MCS-1 device
(:class:`~spotlab.simulators.mcs1_device.Mcs1Device`: event loop, line pacing,
link faults, FIFO, fault log and lab publishing) with the CEN command table and
:class:`CentroidStream`. Each frame the hub triggers its cameras; camera ``c`` exposes
after its own trigger delay, stamps the exposure mid-point with its own clock
(a :class:`DeviceClock` with its own offset and drift) and renders the scene's
markers as blobs (:mod:`spotlab.simulators.blobs`) at that instant.

Scene effects on top of the link faults: ghost reflections and noise blobs
(:class:`BlobModel`), sunlight on a camera (thousands of blobs: the camera
overflows) and a camera going offline for a while, both timed in seconds after
``START:``. The truth (:class:`CentroidTruth`) is written as npz on close.

Nothing here imports the driver: the device side is written from the spec.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np
import numpy.typing as npt

from spotlab.geometry import Rig
from spotlab.simulators import centroid_wire as cw
from spotlab.simulators.blob_optics import Optics
from spotlab.simulators.blobs import BlobModel, CameraBlobs, render_cameras, sight_blocked
from spotlab.simulators.centroid_body import carried_by, segment_capsules
from spotlab.simulators.centroid_poses import body_for
from spotlab.simulators.centroid_truth import CameraTruth, CentroidTruth
from spotlab.simulators.clock import DeviceClock
from spotlab.simulators.commands import Command, CommandError
from spotlab.simulators.faults import FaultInjector
from spotlab.simulators.lab import LabPublisher, frame_start
from spotlab.simulators.mcs1_commands import Handler
from spotlab.simulators.mcs1_device import Mcs1Device
from spotlab.simulators.mcs1_stream import Mcs1Stream, TakenFrame
from spotlab.simulators.motions import Motion, reference_markers
from spotlab.simulators.rigs import ring_rig as reference_rig
from spotlab.simulators.truth import TruthRow

F64 = npt.NDArray[np.float64]
FIRMWARE = "1.0"
#: Time after the exposure's end until the frame is queued (readout, centroiding).
PROCESSING_S = 300e-6
#: Sunlight blobs per frame on a sunlit camera.
SUN_BLOBS = 3000
FIFO_BYTES = 1 << 20
#: Frames whose marker positions are computed in one pass (fewer for large scenes).
SCENE_BLOCK = 32


@dataclass
class CenConfig:
    """Hub configuration (the spec's defaults after reset or ``INIT:``)."""

    rate_mhz: int = 100_000
    camera_mask: int = 0xFF
    exposure_us: int = 500
    threshold: int = 128
    max_blobs: int = 256

    def cameras(self) -> list[int]:
        """Enabled cameras, increasing."""
        return [c for c in range(cw.MAX_CAMERAS) if self.camera_mask >> c & 1]


@dataclass(frozen=True)
class Episode:
    """A scene event on one camera from ``at_s`` for ``duration_s`` seconds after ``START:``."""

    camera: int
    at_s: float
    duration_s: float

    def active(self, camera: int, t_s: float) -> bool:
        """Whether it applies to ``camera`` at ``t_s`` seconds after ``START:``."""
        return camera == self.camera and self.at_s <= t_s < self.at_s + self.duration_s


class CentroidStream(Mcs1Stream):
    """Hub frames of one ``START:`` .. ``STOP:`` period (see the module docstring)."""

    def __init__(self, device: CentroidDevice, config: CenConfig, start_ns: int, index: int):
        self.device = device
        self.cconfig = config
        self.cams = config.cameras()
        super().__init__(device.clock, index, config.rate_mhz, start_ns)
        cells = (len(self.cams) + 1) * device.n_markers
        #: Frames whose scene is computed at once (:meth:`_scene`).
        self._block = max(1, min(SCENE_BLOCK, 20_000 // max(cells, 1)))
        self._block_start = -1
        self._block_w_trig = np.zeros(0)
        self._block_times = np.zeros((0, len(self.cams) + 1))
        self._block_X = np.zeros((0, len(self.cams) + 1, device.n_markers, 3))

    def _scene(self) -> tuple[float, F64, F64]:
        """The trigger (world ns), the scene times (n + 1,) s of each camera's exposure
        mid-point and the hub's, and the markers there (n + 1, M, 3) mm, of this frame.

        Frame times follow from the frame number alone (:func:`frame_start`), so the
        scene of :attr:`_block` frames is computed in one pass; each is the same, to
        the bit, as the frame's own.
        """
        k = self.frame_no
        if not self._block_start <= k < self._block_start + self._block_w_trig.size:
            dev, half = self.device, self.cconfig.exposure_us * 0.5e-6
            osc0 = [self._osc0] + [
                frame_start(self.clock, self.start_osc, self.period_s, i)[1]
                for i in range(k + 1, k + self._block)
            ]
            w_trig = self.clock.world_ns(np.array(osc0))  # (B,)
            w_exp = w_trig[:, None] + (dev.trigger_delay_s[self.cams] + half) * 1e9  # (B, n)
            t_mid = (w_trig + half * 1e9 - self.clock.epoch_ns) * 1e-9
            times = np.concatenate([(w_exp - self.clock.epoch_ns) * 1e-9, t_mid[:, None]], 1)
            X = dev.positions(times.reshape(-1))
            self._block_start, self._block_w_trig, self._block_times = k, w_trig, times
            self._block_X = X.reshape(*times.shape, *X.shape[1:])
        i = k - self._block_start
        return float(self._block_w_trig[i]), self._block_times[i], self._block_X[i]

    def _ready_osc(self, osc0: float) -> float:
        """After the latest camera's exposure, and the readout."""
        return osc0 + self.device.max_delay_s + self.cconfig.exposure_us * 1e-6 + PROCESSING_S

    def take(self) -> TakenFrame:
        """Expose every enabled camera, render the blobs, write the truth, schedule the next."""
        dev, cfg = self.device, self.cconfig
        w_trig, times, X_both = self._scene()  # times (n + 1,), X_both (n + 1, M, 3)
        since_start = (w_trig - self.start_ns) * 1e-9
        half = cfg.exposure_us * 0.5e-6
        w_exp = w_trig + (dev.trigger_delay_s[self.cams] + half) * 1e9  # (n,)
        scene_s, t_mid = times[:-1], float(times[-1])
        online = [
            not any(e.active(c, since_start) for e in dev.camera_off) for c in self.cams
        ] if dev.camera_off else [True] * len(self.cams)  # fmt: skip
        X_all = X_both[:-1]
        hidden = dev.occluded(X_all[0], self.cams)
        live = [j for j, c in enumerate(self.cams) if online[j]]
        sun = [
            SUN_BLOBS if any(e.active(self.cams[j], since_start) for e in dev.sunlight) else 0
            for j in live
        ] if dev.sunlight else [0] * len(live)  # fmt: skip
        rendered = dict(
            zip(live, dev.render_many([self.cams[j] for j in live], X_all[live], hidden[live], sun),
                strict=True)
        )  # fmt: skip
        keep = {j: min(b.uv.shape[0], cfg.max_blobs) for j, b in rendered.items()}
        sent = dict(
            zip(rendered, _quantised(list(rendered.values()), list(keep.values())), strict=True)
        )
        records = []
        truth_cams: list[CameraTruth] = []
        for j, c in enumerate(self.cams):
            if j not in rendered:
                records.append(cw.CameraRecord(c, cw.CAM_OFFLINE, 0, self.frame_no, 0, _NO_BLOBS))
                truth_cams.append(None)
                continue
            blobs = rendered[j]
            n_found = blobs.uv.shape[0]
            tick = round(dev.camera_clocks[c].device_us(round(w_exp[j])))
            records.append(
                cw.CameraRecord(
                    c, cw.CAM_OVERFLOW if n_found > keep[j] else 0, n_found, self.frame_no, tick,
                    sent[j],
                )
            )  # fmt: skip
            truth_cams.append((blobs, keep[j], tick, float(scene_s[j])))
        payload = cw.cen_payload(
            self.frame_no, self._tick, 0, cfg.camera_mask, cfg.max_blobs, cfg.exposure_us,
            cfg.threshold, records,
        )  # fmt: skip
        row = TruthRow(
            stream=self.index, frame_no=self.frame_no, world_ns=w_trig, device_us=self._tick,
            led_ids=np.zeros(0, dtype=np.int64), positions=np.zeros((0, 3)),
        )  # fmt: skip
        if dev.truth is not None:
            dev.truth.add(row, t_mid, X_both[-1], self.cams, truth_cams)
        return self._finish(payload, row)

    def _frame(self, seq: int, payload: bytes, flags: int) -> bytes:
        return cw.cen_frame(seq, payload, flags)


_NO_BLOBS = cw.quantise_blobs(np.zeros((0, 2)), [], [], [])


def _quantised(cameras: list[CameraBlobs], keep: list[int]) -> list[npt.NDArray[np.void]]:
    """The wire blobs of each camera: its first ``keep`` blobs, all cameras quantised at once."""
    if not cameras:
        return []
    cut = [
        (b.uv[:k], b.area[:k], b.peak[:k], b.flags[:k]) for b, k in zip(cameras, keep, strict=True)
    ]
    blobs = cw.quantise_blobs(*(np.concatenate(col) for col in zip(*cut, strict=True)))
    ends = np.cumsum(keep).tolist()
    return [blobs[e - k : e] for e, k in zip(ends, keep, strict=True)]


class CentroidDevice(Mcs1Device[CenConfig]):
    """A CEN hub with its cameras, as seen from its serial port.

    Parameters
    ----------
    rig : Rig, optional
        The cameras (default: :func:`spotlab.simulators.rigs.ring_rig`: 8 of 1280 x 1024).
    markers : int
        Markers: the first of the 40 of :class:`GaitBody`, then static reference
        markers beyond 40 (ignored with ``motion``).
    model : BlobModel, optional
        Marker size, noise, ghosts.
    clock : DeviceClock, optional
        The hub's clock.
    camera_clocks : sequence of DeviceClock, optional
        One per camera (default: seeded offsets of 0-100 s and drifts of +-20 ppm
        on top of the hub's).
    faults : FaultInjector, optional
        Link faults.
    sunlight, camera_off : sequence of Episode
        Sunlit cameras and cameras offline, in seconds after ``START:``.
    occlusion : bool
        Body segments hide markers.
    body_motion : str
        What the body does: ``walk``, ``static`` or ``rom``
        (:func:`spotlab.simulators.centroid_poses.body_for`).
    motion : Motion, optional
        What the cameras see instead of the walking body: its markers, labels and
        positions (a wand dance, a static L-frame); no body occludes them.
    serial, seed, fault_log, default_rate_hz, now_ns, lab :
        As :class:`~spotlab.simulators.mcs1_device.Mcs1Device`.
    truth : path, optional
        Truth npz to write on close (:class:`CentroidTruth`).
    """

    BAUD_RATES: ClassVar[Mapping[int, int]] = cw.CEN_BAUD_RATES
    RATE_RANGE_MHZ: ClassVar[tuple[int, int]] = (1_000, 2_000_000)

    def __init__(
        self,
        rig: Rig | None = None,
        markers: int = 40,
        model: BlobModel | None = None,
        clock: DeviceClock | None = None,
        camera_clocks: Sequence[DeviceClock] | None = None,
        faults: FaultInjector | None = None,
        *,
        sunlight: Sequence[Episode] = (),
        camera_off: Sequence[Episode] = (),
        occlusion: bool = True,
        serial: str = "SIM00091",
        seed: int = 0,
        truth: str | Path | None = None,
        fault_log: str | Path | None = None,
        default_rate_hz: float = 100.0,
        now_ns: int | None = None,
        lab: LabPublisher | None = None,
        body_motion: str = "walk",
        motion: Motion | None = None,
    ) -> None:
        self.rig = rig if rig is not None else reference_rig(8)
        n_cams = len(self.rig.cameras)
        if not 1 <= n_cams <= cw.MAX_CAMERAS:
            raise ValueError(f"a CEN hub has 1-{cw.MAX_CAMERAS} cameras, got {n_cams}")
        if markers < 1:
            raise ValueError(f"markers must be >= 1, got {markers}")
        self.model = model if model is not None else BlobModel()
        self.body = body_for(body_motion, seed)
        #: A ROM subject follows the operator: it stands in the neutral pose until the
        #: capture starts (the first ``START:``), and its course runs from there.
        self.follows_start = body_motion == "rom" and motion is None
        self.body_origin_s: float | None = None if self.follows_start else 0.0
        self.motion = motion
        if motion is not None:
            markers = motion.n_markers
        self.n_markers = markers
        self.labels = (
            motion.labels
            if motion is not None
            else (self.body.labels + reference_markers(max(markers - 40, 0), seed).labels)[:markers]
        )
        self._static: Motion = reference_markers(max(markers - 40, 1), seed)
        self.sunlight = tuple(sunlight)
        self.camera_off = tuple(camera_off)
        self.occlusion = occlusion
        rng = np.random.default_rng(np.random.SeedSequence([seed, 0xCE17]))
        self.trigger_delay_s = rng.uniform(0.0, 20e-6, n_cams)
        self.max_delay_s = float(self.trigger_delay_s.max())
        self.ghost_pairs = rng.random((n_cams, markers)) < self.model.ghost_rate
        self._blob_rng = np.random.default_rng(np.random.SeedSequence([seed, 0xB10B]))
        self._on_capsule = carried_by(40)
        #: The rig's cameras stacked once (every frame renders through them).
        self._optics = Optics.of(self.rig.cameras)
        self._on = np.zeros((markers, self._on_capsule.shape[1]), dtype=bool)
        self._on[:40] = self._on_capsule[: min(markers, 40)]
        super().__init__(
            clock, faults, serial=serial, seed=seed, fault_log=fault_log,
            default_rate_hz=default_rate_hz, fifo_bytes=FIFO_BYTES, now_ns=now_ns, lab=lab,
        )  # fmt: skip
        if camera_clocks is None:
            hub = self.clock
            camera_clocks = [
                DeviceClock(
                    offset_s=hub.offset_s + float(rng.uniform(0, 100)),
                    drift_ppm=hub.drift_ppm + float(rng.uniform(-20, 20)),
                    seed=seed + 1 + c, epoch_ns=hub.epoch_ns,
                )
                for c in range(n_cams)
            ]  # fmt: skip
        if len(camera_clocks) != n_cams:
            raise ValueError(f"{len(camera_clocks)} camera clocks for {n_cams} cameras")
        self.camera_clocks = list(camera_clocks)
        self.truth = CentroidTruth(truth, self) if truth is not None else None

    # -- the scene -----------------------------------------------------------------
    def positions(self, scene_s: F64) -> F64:
        """All emitted markers at times (K,) s -> (K, M, 3) mm."""
        t = np.asarray(scene_s, dtype=np.float64)
        if self.motion is not None:
            k, m = t.size, self.n_markers
            pos = self.motion.sample(np.repeat(t, m), np.tile(np.arange(m, dtype=np.int64), k))
            return np.asarray(pos.reshape(k, m, 3))
        X = self.body.all_markers(t - (self.body_origin_s or 0.0))
        if self.n_markers <= 40:
            return X[:, : self.n_markers]
        extra = self._static.positions(0.0)[: self.n_markers - 40]
        return np.concatenate([X, np.broadcast_to(extra, (t.size, *extra.shape))], axis=1)

    def occluded(self, X: F64, cameras: list[int]) -> npt.NDArray[np.bool_]:
        """(n, M): markers ``X`` (M, 3) hidden by body segments from these cameras."""
        m = X.shape[0]
        if not self.occlusion or m < 40 or self.motion is not None:
            return np.zeros((len(cameras), m), dtype=bool)
        on = self._on if m == self._on.shape[0] else carried_by(m)
        centers = self._cameras_optics(cameras).centers
        return sight_blocked(centers, X, *segment_capsules(X[:40]), on)

    def _cameras_optics(self, cameras: list[int]) -> Optics:
        """The stacked optics of these cameras of the rig."""
        if cameras == list(range(len(self.rig.cameras))):
            return self._optics
        return self._optics.select(cameras)

    def render(
        self, camera: int, X: F64, sun_blobs: int = 0, hidden: npt.NDArray[np.bool_] | None = None
    ) -> CameraBlobs:
        """One camera's blobs for markers ``X`` (M, 3) (see :func:`render_camera`)."""
        return self.render_many([camera], X[None], None if hidden is None else hidden[None],
                                [sun_blobs])[0]  # fmt: skip

    def render_many(
        self, cameras: list[int], X: F64, hidden: npt.NDArray[np.bool_] | None,
        sun_blobs: list[int],
    ) -> list[CameraBlobs]:  # fmt: skip
        """The blobs of several cameras in one frame, markers ``X`` (n, M, 3) per camera
        (see :func:`render_cameras`)."""
        return render_cameras(
            [self.rig.cameras[c] for c in cameras], X, self.model, self._blob_rng,
            hidden=hidden, ghosts=self.ghost_pairs[cameras], sun_blobs=sun_blobs,
            optics=self._cameras_optics(cameras),
        )  # fmt: skip

    # -- life cycle ----------------------------------------------------------------
    def _flush_truth(self) -> None:
        """The truth npz is written (the port closed)."""
        if self.truth is not None:
            self.truth.write()

    def _close_truth(self) -> None:
        if self.truth is not None:
            self.truth.write()

    # -- MCS-1 hooks ---------------------------------------------------------------
    def _default_config(self) -> CenConfig:
        return CenConfig(
            rate_mhz=self._default_rate_mhz, camera_mask=(1 << len(self.rig.cameras)) - 1
        )

    def version_text(self) -> str:
        """``CEN <firmware> <serial> <cameras> <max blobs> <camera tick Hz>``."""
        n = len(self.rig.cameras)
        return f"CEN {FIRMWARE} {self.serial} {n} {cw.MAX_BLOBS} {cw.CAMERA_TICK_HZ}"

    def _family_handlers(self) -> dict[str, Handler]:
        return {
            "CAMS": self._cen_cams, "EXPO": self._cen_expo, "THRS": self._cen_thrs,
            "BLOB": self._cen_blob, "CONF": self._cen_conf,
        }  # fmt: skip

    def _check_start(self) -> None:
        cfg = self._config
        n = len(cfg.cameras())
        if cfg.exposure_us * cfg.rate_mhz > 900_000_000:
            raise CommandError(0x23)
        longest = cw.cen_frame_length(n, n * cfg.max_blobs) - cw.FRAME_OVERHEAD
        if longest > cw.MAX_PAYLOAD:
            raise CommandError(0x80)
        if cfg.rate_mhz * cw.cen_frame_length(n, 0) * 10 > 800 * self._baud:
            raise CommandError(0x80)

    def _new_stream(self, t: int, index: int) -> Mcs1Stream:
        if self.body_origin_s is None:  # the first START: a ROM subject begins now
            self.body_origin_s = (t - self.clock.epoch_ns) * 1e-9
        return CentroidStream(self, CenConfig(**self._config.__dict__), t, index)

    # -- CEN verbs -----------------------------------------------------------------
    def _cen_cams(self, cmd: Command, t: int) -> str:
        self._not_streaming()
        self._config.camera_mask = self._int_param(cmd, 1, (1 << len(self.rig.cameras)) - 1)
        return self._configured()

    def _cen_conf(self, cmd: Command, t: int) -> str:
        """The configuration in force, as the commands that set it (centroid.md §2)."""
        self._no_params(cmd)
        c = self._config
        return (
            f"CONF RATE={c.rate_mhz} CAMS={c.camera_mask} EXPO={c.exposure_us} "
            f"THRS={c.threshold} BLOB={c.max_blobs}"
        )

    def _cen_expo(self, cmd: Command, t: int) -> str:
        self._not_streaming()
        self._config.exposure_us = self._int_param(cmd, 20, 10_000)
        return self._configured()

    def _cen_thrs(self, cmd: Command, t: int) -> str:
        self._not_streaming()
        self._config.threshold = self._int_param(cmd, 1, 254)
        return self._configured()

    def _cen_blob(self, cmd: Command, t: int) -> str:
        self._not_streaming()
        self._config.max_blobs = self._int_param(cmd, 1, cw.MAX_BLOBS)
        return self._configured()


__all__ = ["CenConfig", "CentroidDevice", "CentroidStream", "Episode"]
