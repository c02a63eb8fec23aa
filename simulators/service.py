"""Simulated SPX systems as the command line and the tests start them.

One options dataclass describes a simulated system; :func:`build_device`
turns it into a :class:`SelspotDevice`, :func:`serve_pty` and :func:`serve_tcp`
serve one on a pseudo-terminal or a local TCP port, and :func:`url_for` gives
the equivalent in-process ``sim://`` URL (for ``serial.serial_for_url``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any
from urllib.parse import urlsplit

from spotlab.simulators import mcs1_service as mcs1
from spotlab.simulators.faults import FaultInjector
from spotlab.simulators.lab import PulseSource, lab_dir
from spotlab.simulators.mcs1_service import POWER_UP_LEAD_NS
from spotlab.simulators.motions import MOTIONS, Delayed, make_motion
from spotlab.simulators.scene import Ambient, Mirror, Scene, ring_rig
from spotlab.simulators.selspot import SelspotDevice
from spotlab.simulators.timer import TimerDevice

if TYPE_CHECKING:
    from spotlab.simulators.mcs1_device import Mcs1Device
    from spotlab.simulators.transports.pty import PtyServer
    from spotlab.simulators.transports.tcp import TcpServer


@dataclass
class SelspotSimOptions:
    """A simulated SPX system.

    Parameters
    ----------
    cameras : int
        Cameras in the rig (1-4); ``VER:0`` reports it as the maximum for ``CAMS:``.
    leds : int
        LEDs the motion carries (LED ids 0 .. leds-1).
    rate_hz : float
        Frame rate after reset or ``INIT:`` (the host may set another with ``RATE:``).
    seed : int
        Seed of noise, motion and random faults.
    truth, fault_log : Path, optional
        Ground-truth CSV and fault-log JSON to write.
    faults : str
        Fault schedule (see :mod:`spotlab.simulators.faults`).
    fault_rate : float
        Random frame faults per data frame.
    clock_offset_s, clock_drift_ppm, clock_jitter_s : float
        The device clock (see :class:`DeviceClock`).
    clock_steps : tuple of (float, float)
        Counter steps ``(at_s, delta_s)``: ``at_s`` s after power-up the counter jumps by
        ``delta_s`` s (frame pacing and frame pulses are not affected).
    motion : str
        ``wand``, ``cluster``, ``gait`` or the path of a C3D file.
    serial : str
        Serial number in the ``VER:0`` reply.
    ambient : float
        Ambient infrared level on every detector (intensity units).
    floor_reflectance : float
        Reflectance of the floor (a mirror at z = 0); 0 for none.
    rig_out : Path, optional
        Where to write the simulated cameras as a spotlab rig (TOML, detector counts;
        see :meth:`PsdModel.rig`): the truth a calibration should find.
    ring_phase_deg : float
        Turns the camera ring about the vertical (degrees): another system's cameras.
    scene_epoch_s : float, optional
        World time (``time.monotonic()`` s) at which the motion starts; None: at the
        device's power-up. Systems of one lab given the same epoch see the same markers
        at the same world instants.
    lab_name : str
        Name under which the frame pulses are published to the lab folder (a
        timer's ``--input N=NAME``); empty: not published.
    lab : Path, optional
        The lab folder (default: :func:`~spotlab.simulators.lab.lab_dir`).

    Notes
    -----
    The baud rate is not an option: the device starts at 9600 and follows
    ``COMM:`` as negotiated by the host.
    """

    cameras: int = 2
    leds: int = 8
    rate_hz: float = 100.0
    seed: int = 0
    truth: Path | None = None
    fault_log: Path | None = None
    faults: str = ""
    fault_rate: float = 0.0
    clock_offset_s: float = 0.0
    clock_drift_ppm: float = 0.0
    clock_jitter_s: float = 0.0
    clock_steps: tuple[tuple[float, float], ...] = ()
    motion: str = "wand"
    serial: str = "SIM00042"
    ambient: float = 0.0
    floor_reflectance: float = 0.05
    rig_out: Path | None = None
    ring_phase_deg: float = 0.0
    scene_epoch_s: float | None = None
    lab_name: str = ""
    lab: Path | None = None

    def validate(self) -> None:
        """Raise ValueError naming the first bad option."""
        if not 1 <= self.cameras <= 4:
            raise ValueError(f"cameras must be 1 to 4, got {self.cameras}")
        if not 1 <= self.leds <= 128:
            raise ValueError(f"leds must be 1 to 128, got {self.leds}")
        if not 1.0 <= self.rate_hz <= 10_000.0:
            raise ValueError(f"rate must be 1 Hz to 10 kHz, got {self.rate_hz}")
        if not 0.0 <= self.floor_reflectance <= 1.0:
            raise ValueError(f"floor reflectance must be 0 to 1, got {self.floor_reflectance}")
        if self.motion not in MOTIONS and not Path(self.motion).is_file():
            raise ValueError(
                f"motion {self.motion!r} is neither {', '.join(MOTIONS)} nor a C3D file"
            )


def build_scene(options: SelspotSimOptions, epoch_ns: int | None = None) -> Scene:
    """The scene of a simulated system: ring rig, floor mirror, ambient light, motion.

    ``epoch_ns``: the device's power-up (world ns), where its scene time starts; with
    ``options.scene_epoch_s`` the motion is shifted to start at that world time instead.
    """
    mirrors = (
        [Mirror(reflectance=options.floor_reflectance)] if options.floor_reflectance > 0 else []
    )
    motion = make_motion(options.motion, options.leds, options.seed)
    if options.scene_epoch_s is not None and epoch_ns is not None:
        motion = Delayed(motion, epoch_ns * 1e-9 - options.scene_epoch_s)
    return Scene(
        motion=motion,
        cameras=ring_rig(options.cameras, phase_deg=options.ring_phase_deg),
        mirrors=mirrors,
        ambient=Ambient(level=options.ambient),
    )


def build_device(options: SelspotSimOptions, now_ns: int | None = None) -> SelspotDevice:
    """A powered-up simulated SPX device (banner queued at 9600 baud)."""
    options.validate()
    clock = mcs1.device_clock(options, now_ns, options.clock_steps)
    faults = FaultInjector(options.faults, rate=options.fault_rate, seed=options.seed)
    scene = build_scene(options, clock.epoch_ns)
    device = SelspotDevice(
        scene,
        clock,
        faults,
        serial=options.serial,
        seed=options.seed,
        truth=options.truth,
        fault_log=options.fault_log,
        default_rate_hz=options.rate_hz,
        now_ns=clock.epoch_ns,
        lab=mcs1.lab_publisher(options, clock),
    )
    if options.rig_out is not None:
        device.psd.rig(scene.cameras).save(options.rig_out)
    return device


def url_for(options: SelspotSimOptions) -> str:
    """The ``sim://selspot?...`` URL of these options (defaults left out)."""
    return mcs1.options_url("selspot", options, safe="/@:,.-")


def options_from_url(url: str) -> SelspotSimOptions:
    """Parse ``sim://selspot?cameras=4&leds=32&rate=200&faults=...``.

    Raises
    ------
    ValueError
        For another family, an unknown option or a value of the wrong type.
    """
    options = mcs1.parse_options_url(url, "selspot", SelspotSimOptions)
    options.validate()
    return options


def serve_pty(options: SelspotSimOptions) -> PtyServer:
    """Start serving a simulated device on a pseudo-terminal; ``.path`` is the stable link."""
    return mcs1.serve_device_pty(lambda now_ns: build_device(options, now_ns), "selspot")


def serve_tcp(options: SelspotSimOptions, port: int = 0) -> TcpServer:
    """Start serving a simulated device on 127.0.0.1:``port`` (0: any); ``.url`` is ``socket://``."""
    from spotlab.simulators.transports.tcp import TcpServer

    server = TcpServer(
        build_device(options, now_ns=time.monotonic_ns() - POWER_UP_LEAD_NS), port=port
    )
    server.start()
    return server


@dataclass
class TimerSimOptions:
    """A simulated TMR timer/sync unit.

    Parameters
    ----------
    rate_hz : float
        Frame rate after reset or ``INIT:``.
    seed : int
        Seed of capture jitter, line garbling and random faults.
    truth : Path, optional
        Frame truth CSV; the edge truth goes to ``<truth>.edges.csv``.
    fault_log : Path, optional
        Fault-log JSON.
    faults : str
        Fault schedule.
    fault_rate : float
        Random frame faults per data frame.
    clock_offset_s, clock_drift_ppm, clock_jitter_s : float
        The unit's clock; the jitter applies to frame instants and edge captures.
    clock_steps : tuple of (float, float)
        Counter steps ``(at_s, delta_s)`` after power-up, as :class:`DeviceClock` takes them.
    inputs : str
        Wiring, ``"0=selspot,1=selspot1"``: input number = lab name of a device.
    lab : Path, optional
        The lab folder (default: :func:`~spotlab.simulators.lab.lab_dir`).
    serial : str
        Serial number in the ``VER:0`` reply.
    """

    rate_hz: float = 100.0
    seed: int = 0
    truth: Path | None = None
    fault_log: Path | None = None
    faults: str = ""
    fault_rate: float = 0.0
    clock_offset_s: float = 0.0
    clock_drift_ppm: float = 0.0
    clock_jitter_s: float = 0.0
    clock_steps: tuple[tuple[float, float], ...] = ()
    inputs: str = ""
    lab: Path | None = None
    serial: str = "SIM00077"

    def wiring(self) -> dict[int, str]:
        """``inputs`` as input number -> lab name; ValueError if malformed."""
        out: dict[int, str] = {}
        for item in filter(None, self.inputs.split(",")):
            number, sep, name = item.partition("=")
            if not sep or not number.strip().isdigit() or not name.strip():
                raise ValueError(f"an input is wired as N=SOURCE, got {item!r}")
            if not 0 <= int(number) <= 7:
                raise ValueError(f"timer inputs are 0-7, got {number}")
            out[int(number)] = name.strip()
        return out

    def validate(self) -> None:
        """Raise ValueError naming the first bad option."""
        if not 1.0 <= self.rate_hz <= 10_000.0:
            raise ValueError(f"rate must be 1 Hz to 10 kHz, got {self.rate_hz}")
        self.wiring()


def build_timer_device(options: TimerSimOptions, now_ns: int | None = None) -> TimerDevice:
    """A powered-up simulated TMR unit, its inputs wired through the lab folder."""
    options.validate()
    clock = mcs1.device_clock(options, now_ns, options.clock_steps)
    folder = lab_dir(options.lab)
    return TimerDevice(
        clock,
        FaultInjector(options.faults, rate=options.fault_rate, seed=options.seed),
        inputs={i: PulseSource(folder, name) for i, name in options.wiring().items()},
        serial=options.serial,
        seed=options.seed,
        truth=options.truth,
        fault_log=options.fault_log,
        default_rate_hz=options.rate_hz,
        now_ns=clock.epoch_ns,
    )


def serve_timer_pty(options: TimerSimOptions) -> PtyServer:
    """Serve a simulated TMR unit on a pseudo-terminal; ``.path`` is the stable link."""
    return mcs1.serve_device_pty(lambda now_ns: build_timer_device(options, now_ns), "timer")


def timer_url_for(options: TimerSimOptions) -> str:
    """The ``sim://timer?...`` URL of these options (defaults left out)."""
    return mcs1.options_url("timer", options)


def device_from_url(url: str, now_ns: int | None = None) -> Mcs1Device[Any]:
    """The simulated device a ``sim://selspot|timer|centroid|coda?...`` URL describes."""
    if urlsplit(url).netloc == "coda":
        from spotlab.simulators import coda_service as csx

        return csx.build_coda_device(csx.coda_options_from_url(url), now_ns=now_ns)
    if urlsplit(url).netloc == "centroid":
        from spotlab.simulators import centroid_service as cen

        return cen.build_centroid_device(cen.centroid_options_from_url(url), now_ns=now_ns)
    if urlsplit(url).netloc == "timer":
        options = mcs1.parse_options_url(url, "timer", TimerSimOptions)
        return build_timer_device(options, now_ns=now_ns)
    return build_device(options_from_url(url), now_ns=now_ns)
