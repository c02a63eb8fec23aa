"""Simulated CEN hubs as the command line and the tests start them.

:class:`CentroidSimOptions` describes one; :func:`build_centroid_device` turns it
into a :class:`CentroidDevice`, :func:`serve_centroid_pty` serves one on a
pseudo-terminal and :func:`centroid_url_for` gives the in-process
``sim://centroid?...`` URL.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, fields
from pathlib import Path
from typing import TYPE_CHECKING
from urllib.parse import quote

from spotlab.simulators.blobs import BlobModel
from spotlab.simulators.centroid import CentroidDevice, Episode
from spotlab.simulators.centroid_poses import BODY_MOTIONS
from spotlab.simulators.clock import DeviceClock
from spotlab.simulators.faults import FaultInjector
from spotlab.simulators.lab import LabPublisher, lab_dir
from spotlab.simulators.rigs import ring_rig
from spotlab.simulators.service import (
    _URL_SHORT,
    FRAME_PULSE_WIDTH_S,
    POWER_UP_LEAD_NS,
    _options_from_url,
)

if TYPE_CHECKING:
    from spotlab.simulators.transports.pty import PtyServer


def parse_episodes(text: str, what: str) -> tuple[Episode, ...]:
    """``"CAM@AT:DURATION,..."`` (camera index, seconds after ``START:``) as episodes.

    Raises
    ------
    ValueError
        Naming the malformed item.
    """
    out = []
    for item in filter(None, (s.strip() for s in text.split(","))):
        cam, at_sep, rest = item.partition("@")
        at, sep, dur = rest.partition(":")
        try:
            if not at_sep or not sep:
                raise ValueError
            episode = Episode(int(cam), float(at), float(dur))
        except ValueError:
            raise ValueError(f"{what} {item!r}: expected CAMERA@AT:DURATION") from None
        if episode.camera < 0 or episode.at_s < 0 or not episode.duration_s > 0:
            raise ValueError(f"{what} {item!r}: camera and AT must be >= 0, DURATION > 0")
        out.append(episode)
    return tuple(out)


@dataclass
class CentroidSimOptions:
    """A simulated CEN hub.

    Parameters
    ----------
    cameras : int
        Cameras: the first of :func:`ring_rig` (8 cameras 1280 x 1024 on a 4 m ring), or
        a ring of that many when more than 8 (1-16).
    markers : int
        Markers (the 40 of the walking body first, static ones beyond).
    motion : str
        What the body does: ``walk``, ``static`` (standing still) or ``rom`` (range of
        motion), see :mod:`spotlab.simulators.centroid_poses`.
    rate_hz : float
        Frame rate after reset or ``INIT:``.
    seed : int
        Seed of noise, ghosts, camera clocks and random faults.
    truth, fault_log, rig_out : Path, optional
        Truth npz, fault-log JSON, and the true calibration (``Rig.save`` TOML).
    faults : str
        Link fault schedule (see :mod:`spotlab.simulators.faults`).
    fault_rate : float
        Random frame faults per data frame.
    clock_offset_s, clock_drift_ppm, clock_jitter_s : float
        The hub's clock; every camera's clock adds its own seeded offset and drift.
    ghost_rate : float
        Fraction of (camera, marker) pairs that see the marker's floor reflection.
    noise_blobs : float
        Random noise blobs per camera and frame.
    centroid_noise_px : float
        Centroid noise (px RMS per coordinate).
    sunlight, camera_off : str
        ``CAM@AT:DURATION,...``: cameras sunlit (thousands of blobs) or offline.
    occlusion : int
        1: body segments hide markers; 0: no occlusion.
    lab_name, lab :
        Publish the frame pulses to the lab folder under this name.
    serial : str
        Serial number in the ``VER:0`` reply.
    """

    cameras: int = 8
    markers: int = 40
    motion: str = "walk"
    rate_hz: float = 100.0
    seed: int = 0
    truth: Path | None = None
    fault_log: Path | None = None
    rig_out: Path | None = None
    faults: str = ""
    fault_rate: float = 0.0
    clock_offset_s: float = 0.0
    clock_drift_ppm: float = 0.0
    clock_jitter_s: float = 0.0
    ghost_rate: float = 0.02
    noise_blobs: float = 0.02
    centroid_noise_px: float = 0.07
    sunlight: str = ""
    camera_off: str = ""
    occlusion: int = 1
    lab_name: str = ""
    lab: Path | None = None
    serial: str = "SIM00091"

    def validate(self) -> None:
        """Raise ValueError naming the first bad option."""
        if not 1 <= self.cameras <= 16:
            raise ValueError(f"cameras must be 1 to 16, got {self.cameras}")
        if not 1 <= self.markers <= 512:
            raise ValueError(f"markers must be 1 to 512, got {self.markers}")
        if self.motion not in BODY_MOTIONS:
            raise ValueError(f"motion {self.motion!r}: expected one of {', '.join(BODY_MOTIONS)}")
        if not 1.0 <= self.rate_hz <= 2000.0:
            raise ValueError(f"rate must be 1 Hz to 2 kHz, got {self.rate_hz}")
        if not 0.0 <= self.ghost_rate <= 1.0:
            raise ValueError(f"ghost rate must be 0 to 1, got {self.ghost_rate}")
        if self.noise_blobs < 0 or self.centroid_noise_px < 0:
            raise ValueError("noise blobs and centroid noise must be >= 0")
        for text, what in ((self.sunlight, "sunlight"), (self.camera_off, "camera-off")):
            for e in parse_episodes(text, what):
                if e.camera >= self.cameras:
                    raise ValueError(f"{what}: camera {e.camera} of {self.cameras} (0-based)")


def build_centroid_device(options: CentroidSimOptions, now_ns: int | None = None) -> CentroidDevice:
    """A powered-up simulated CEN hub (and its rig written to ``rig_out``)."""
    options.validate()
    clock = DeviceClock(
        offset_s=options.clock_offset_s, drift_ppm=options.clock_drift_ppm,
        jitter_s=options.clock_jitter_s, seed=options.seed, epoch_ns=now_ns,
    )  # fmt: skip
    rig = ring_rig(max(options.cameras, 8))
    if options.cameras < 8:
        rig = type(rig)(rig.cameras[: options.cameras])
    model = BlobModel(
        centroid_noise_px=options.centroid_noise_px, ghost_rate=options.ghost_rate,
        noise_blobs=options.noise_blobs,
    )  # fmt: skip
    device = CentroidDevice(
        rig, options.markers, model, clock, None,
        FaultInjector(options.faults, rate=options.fault_rate, seed=options.seed),
        sunlight=parse_episodes(options.sunlight, "sunlight"),
        camera_off=parse_episodes(options.camera_off, "camera-off"),
        occlusion=bool(options.occlusion), serial=options.serial, seed=options.seed,
        truth=options.truth, fault_log=options.fault_log, default_rate_hz=options.rate_hz,
        body_motion=options.motion,
        now_ns=clock.epoch_ns,
        lab=(
            LabPublisher(lab_dir(options.lab), options.lab_name, clock, FRAME_PULSE_WIDTH_S)
            if options.lab_name
            else None
        ),
    )  # fmt: skip
    if options.rig_out is not None:
        rig.save(options.rig_out)
    return device


def serve_centroid_pty(options: CentroidSimOptions) -> PtyServer:
    """Serve a simulated CEN hub on a pseudo-terminal; ``.path`` is the stable link."""
    from spotlab.simulators.transports.pty import PtyServer

    device = build_centroid_device(options, now_ns=time.monotonic_ns() - POWER_UP_LEAD_NS)
    server = PtyServer(device, name="centroid")
    server.start()
    return server


def centroid_url_for(options: CentroidSimOptions) -> str:
    """The ``sim://centroid?...`` URL of these options (defaults left out)."""
    default = CentroidSimOptions()
    parts = []
    for f in fields(options):
        value = getattr(options, f.name)
        if value == getattr(default, f.name) or value is None:
            continue
        parts.append(f"{_URL_SHORT.get(f.name, f.name)}={quote(str(value), safe='/@:,.-=')}")
    return "sim://centroid" + ("?" + "&".join(parts) if parts else "")


def centroid_options_from_url(url: str) -> CentroidSimOptions:
    """Parse ``sim://centroid?cameras=8&markers=40&rate=300...`` (ValueError if malformed)."""
    options = _options_from_url(url, "centroid", CentroidSimOptions)
    options.validate()
    return options
