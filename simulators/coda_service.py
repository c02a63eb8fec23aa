"""Simulated CSX scanners as the command line and the tests start them.

:class:`CodaSimOptions` describes one; :func:`build_coda_device` turns it into a
:class:`~spotlab.simulators.coda.CodaDevice`, :func:`serve_coda_pty` serves one on
a pseudo-terminal, :func:`serve_coda_tcp` on a TCP port, and :func:`coda_url_for`
gives the in-process ``sim://coda?...`` URL.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from spotlab.simulators import mcs1_service as mcs1
from spotlab.simulators.coda import CodaDevice, CodaFaults
from spotlab.simulators.coda_scene import Pose
from spotlab.simulators.faults import FaultInjector

if TYPE_CHECKING:
    from spotlab.simulators.transports.pty import PtyServer
    from spotlab.simulators.transports.tcp import TcpServer

#: World time a TCP-served device was powered up before it is served (as the SPX one).
POWER_UP_LEAD_NS = 1_000_000


@dataclass
class CodaSimOptions:
    """A simulated CSX scanner.

    Parameters
    ----------
    markers : int
        Markers in the scene, IDs 1..M (colour codes of coda.md §2), 1-56.
    rate_hz : float
        Scan rate after reset or ``INIT:`` (50-800 Hz).
    base_mm : float
        The unit's mirror base (reported in ``VER:0``).
    seed : int
        Seed of noise, faults and line garbling.
    truth, fault_log : Path, optional
        Frame truth CSV (:mod:`spotlab.simulators.coda`) and fault-log JSON.
    faults : str
        Link fault schedule (see :mod:`spotlab.simulators.faults`).
    fault_rate : float
        Random link frame faults per data frame.
    clock_offset_s, clock_drift_ppm, clock_jitter_s : float
        The unit's clock.
    colour_rate, ghost_rate, occlusion_rate : float
        The scanner's own faults per marker and scan (occlusion: per mirror too).
    ambient : float
        Ambient light 0-1.
    pose : str
        ``"YAW,X,Y,Z"``: the unit turned YAW degrees about the vertical (counter-clockwise
        from above) at (X, Y, Z) mm of the world frame; empty: at the origin.
    reference : int
        1: the static reference object (IDs 50-53, codes WR, WO, WY, WG) is in the scene.
    lab_name, lab :
        Publish the frame pulses to the lab folder under this name.
    serial : str
        Serial number in the ``VER:0`` reply.
    """

    markers: int = 8
    rate_hz: float = 300.0
    base_mm: float = 1000.0
    seed: int = 0
    truth: Path | None = None
    fault_log: Path | None = None
    faults: str = ""
    fault_rate: float = 0.0
    clock_offset_s: float = 0.0
    clock_drift_ppm: float = 0.0
    clock_jitter_s: float = 0.0
    colour_rate: float = 0.001
    ghost_rate: float = 0.0005
    occlusion_rate: float = 0.001
    ambient: float = 0.0
    pose: str = ""
    reference: int = 0
    lab_name: str = ""
    lab: Path | None = None
    serial: str = "SIM00031"

    def validate(self) -> None:
        """Raise ValueError naming the first bad option."""
        if not 1 <= self.markers <= 56:
            raise ValueError(f"markers must be 1 to 56, got {self.markers}")
        if not 50.0 <= self.rate_hz <= 800.0:
            raise ValueError(f"rate must be 50 to 800 Hz, got {self.rate_hz:g}")
        if not 100.0 <= self.base_mm <= 5000.0:
            raise ValueError(f"the mirror base must be 100 to 5000 mm, got {self.base_mm:g}")
        for name in ("colour_rate", "ghost_rate", "occlusion_rate", "ambient"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"{name.replace('_', ' ')} must be 0 to 1")
        self.unit_pose()

    def unit_pose(self) -> Pose:
        """``pose`` parsed; ValueError if it is not ``YAW,X,Y,Z``."""
        if not self.pose:
            return Pose()
        try:
            yaw, x, y, z = (float(v) for v in self.pose.split(","))
        except ValueError:
            raise ValueError(f"pose must be YAW,X,Y,Z (degrees, mm), got {self.pose!r}") from None
        return Pose(yaw, (x, y, z))


def build_coda_device(options: CodaSimOptions, now_ns: int | None = None) -> CodaDevice:
    """A powered-up simulated CSX scanner."""
    options.validate()
    clock = mcs1.device_clock(options, now_ns)
    rates = CodaFaults(
        colour=options.colour_rate, ghost=options.ghost_rate,
        occlusion=options.occlusion_rate, ambient=options.ambient,
    )  # fmt: skip
    device = CodaDevice(
        clock,
        FaultInjector(options.faults, rate=options.fault_rate, seed=options.seed),
        scene_markers=options.markers, base_mm=options.base_mm, fault_rates=rates,
        pose=options.unit_pose(), reference=bool(options.reference),
        serial=options.serial, seed=options.seed, truth=options.truth,
        fault_log=options.fault_log, default_rate_hz=options.rate_hz, now_ns=clock.epoch_ns,
        lab=mcs1.lab_publisher(options, clock),
    )  # fmt: skip
    return device


def serve_coda_pty(options: CodaSimOptions) -> PtyServer:
    """Serve a simulated CSX scanner on a pseudo-terminal; ``.path`` is the stable link."""
    return mcs1.serve_device_pty(lambda now_ns: build_coda_device(options, now_ns), "coda")


def serve_coda_tcp(options: CodaSimOptions, port: int = 0) -> TcpServer:
    """Serve a simulated CSX scanner on 127.0.0.1:``port`` (0: any); ``.url`` is ``socket://``."""
    from spotlab.simulators.transports.tcp import TcpServer

    device = build_coda_device(options, now_ns=time.monotonic_ns() - POWER_UP_LEAD_NS)
    server = TcpServer(device, port=port)
    server.start()
    return server


def coda_url_for(options: CodaSimOptions) -> str:
    """The ``sim://coda?...`` URL of these options (defaults left out)."""
    return mcs1.options_url("coda", options)


def coda_options_from_url(url: str) -> CodaSimOptions:
    """Parse ``sim://coda?markers=8&rate=300...`` (ValueError if malformed)."""
    options = mcs1.parse_options_url(url, "coda", CodaSimOptions)
    options.validate()
    return options
