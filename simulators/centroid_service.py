"""Simulated CEN hubs as the command line and the tests start them.

:class:`CentroidSimOptions` describes one; :func:`build_centroid_device` turns it
into a :class:`CentroidDevice`, :func:`serve_centroid_pty` serves one on a
pseudo-terminal and :func:`centroid_url_for` gives the in-process
``sim://centroid?...`` URL.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from spotlab.simulators import mcs1_service as mcs1
from spotlab.simulators.blobs import BlobModel
from spotlab.simulators.centroid import CentroidDevice, Episode
from spotlab.simulators.centroid_poses import BODY_MOTIONS
from spotlab.simulators.faults import FaultInjector
from spotlab.simulators.motions import Motion, WandDance, reference_markers
from spotlab.simulators.rigs import ring_rig

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
        Markers: ``walk``: the 40 of the walking body first, static ones beyond;
        ``wand``: on the wand (2 or 3); ``lframe``: the L-frame's 4 first (3-512).
    motion : str
        ``walk`` (the 40-marker body walking), ``static`` (standing still), ``rom``
        (range of motion, :mod:`spotlab.simulators.centroid_poses`), ``wand`` (a passive
        wand waved through the volume, :data:`WAND_VOLUME`) or ``lframe`` (a static
        L-frame on the floor,
        :func:`~spotlab.simulators.motions.reference_markers`).
    wand_length_mm : float
        Distance between the wand's end markers (mm); a 3-marker wand's middle marker
        sits :data:`WAND_MIDDLE` of it from end A.
    rate_hz : float
        Frame rate after reset or ``INIT:``.
    seed : int
        Seed of noise, ghosts, camera clocks and random faults.
    truth, fault_log, rig_out : Path, optional
        Truth npz, fault-log JSON, and the true calibration (``Rig.save`` TOML).
    frame_points_out : Path, optional
        CSV (``X,Y,Z`` mm, one row per marker) of the L-frame's published marker
        coordinates, as its maker states them.
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
    wand_length_mm: float = 500.0
    rate_hz: float = 100.0
    seed: int = 0
    truth: Path | None = None
    fault_log: Path | None = None
    rig_out: Path | None = None
    frame_points_out: Path | None = None
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
        if self.motion not in CENTROID_MOTIONS:
            raise ValueError(
                f"motion {self.motion!r}: expected one of {', '.join(CENTROID_MOTIONS)}"
            )
        low = {"wand": 2, "lframe": 3}.get(self.motion, 1)
        high = 3 if self.motion == "wand" else 512
        if not low <= self.markers <= high:
            raise ValueError(
                f"markers must be {low} to {high} for the {self.motion} motion, got {self.markers}"
            )
        if not 50.0 <= self.wand_length_mm <= 3000.0:
            raise ValueError(f"wand length must be 50 to 3000 mm, got {self.wand_length_mm:g}")
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


#: Scenes of the centroid simulator.
CENTROID_MOTIONS = (*BODY_MOTIONS, "wand", "lframe")
#: Where the wand goes (:class:`WandDance`, mm): the operator walks a 3 x 3 m area and
#: sweeps the wand from 0.2 to 2 m high. The wand is waved 2.5 times as fast as the PSD
#: simulator's (``tempo``): a few seconds cover the volume and most of every camera's image.
WAND_VOLUME: dict[str, Any] = {
    "centre": (0.0, 0.0, 1100.0), "walk": 1000.0, "reach": 500.0, "extent_z": 900.0,
    "radius": 1500.0,
}  # fmt: skip
WAND_TEMPO = 2.5
#: A 3-marker wand's middle marker, from end A, in wand lengths (off-centre: the
#: ends are told apart).
WAND_MIDDLE = 0.4
#: Markers of the L-frame (``lframe``, :func:`reference_markers`).
LFRAME_MARKERS = 4


def centroid_motion(options: CentroidSimOptions) -> Motion | None:
    """The scene of ``options.motion`` (None: the walking body of :class:`CentroidDevice`)."""
    if options.motion == "wand":
        return WandDance(
            options.wand_length_mm, **WAND_VOLUME, seed=options.seed, tempo=WAND_TEMPO,
            middle_mm=WAND_MIDDLE * options.wand_length_mm if options.markers == 3 else None,
        )  # fmt: skip
    if options.motion == "lframe":
        return reference_markers(options.markers, options.seed)
    return None


def write_frame_points(path: Path) -> None:
    """The L-frame's published marker coordinates as CSV (``X,Y,Z`` mm, one row each)."""
    points = reference_markers(LFRAME_MARKERS).points
    path.write_text("X,Y,Z\n" + "".join(f"{x:g},{y:g},{z:g}\n" for x, y, z in points))


def build_centroid_device(options: CentroidSimOptions, now_ns: int | None = None) -> CentroidDevice:
    """A powered-up simulated CEN hub (and its rig written to ``rig_out``)."""
    options.validate()
    clock = mcs1.device_clock(options, now_ns)
    # The rig does not depend on the seed: a lab's cameras stay put between trials.
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
        body_motion=options.motion if options.motion in BODY_MOTIONS else "walk",
        now_ns=clock.epoch_ns, lab=mcs1.lab_publisher(options, clock),
        motion=centroid_motion(options),
    )  # fmt: skip
    if options.rig_out is not None:
        rig.save(options.rig_out)
    if options.frame_points_out is not None:
        write_frame_points(options.frame_points_out)
    return device


def serve_centroid_pty(options: CentroidSimOptions) -> PtyServer:
    """Serve a simulated CEN hub on a pseudo-terminal; ``.path`` is the stable link."""
    return mcs1.serve_device_pty(lambda now_ns: build_centroid_device(options, now_ns), "centroid")


def centroid_url_for(options: CentroidSimOptions) -> str:
    """The ``sim://centroid?...`` URL of these options (defaults left out)."""
    return mcs1.options_url("centroid", options)


def centroid_options_from_url(url: str) -> CentroidSimOptions:
    """Parse ``sim://centroid?cameras=8&markers=40&rate=300...`` (ValueError if malformed)."""
    options = mcs1.parse_options_url(url, "centroid", CentroidSimOptions)
    options.validate()
    return options
