"""Byte-level emulator of the CSX optomechanical scanner (docs/protocols/coda.md).

:class:`CodaDevice` is an MCS-1 device
(:class:`~spotlab.simulators.mcs1_device.Mcs1Device`: event loop, line pacing,
link faults, FIFO, truth and fault log) with the CSX command table, and
:class:`CodaStream` scans the scene of :mod:`spotlab.simulators.coda_scene`:
three mirrors each crossing each marker at its own instant, angle
quantisation, noise growing with distance and ambient light, occlusion, and the
scanner's own faults, each flagged in its record as the spec says: colour
mis-identification (``colour ambiguous``), ID aliasing of table entries beyond
the rate's limit (``aliased``, under the lower-numbered entry's ID) and a
reflection ghost (``ghost suspected``).

The scanner's own faults go into the device's fault log beside the link faults
(``colour``, ``alias``, ``ghost``; source ``device``).

Truth: the frame truth CSV (:mod:`spotlab.simulators.truth`; ``.npz`` arrays of the
same for a path with that suffix, :mod:`spotlab.simulators.truth_npz`) has, per scan, the
world time of the scan start and columns ``led<ID>_x_mm ...`` with every moving
scene marker's true position then (world frame, mm: the scanner frame of a unit
at the origin; a unit placed elsewhere, ``pose``, sees it turned and shifted);
the scene is deterministic (:func:`~spotlab.simulators.coda_scene.marker_positions`),
so the position at any crossing instant follows from it.

Nothing here imports the driver: the device side is written from the spec.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from spotlab.simulators import coda_scene as scene
from spotlab.simulators import coda_wire as cw
from spotlab.simulators.clock import DeviceClock
from spotlab.simulators.commands import Command, CommandError
from spotlab.simulators.faults import FaultEntry, FaultInjector
from spotlab.simulators.lab import LabPublisher
from spotlab.simulators.mcs1_commands import Handler
from spotlab.simulators.mcs1_device import Mcs1Device
from spotlab.simulators.mcs1_stream import Mcs1Stream, TakenFrame
from spotlab.simulators.truth import TruthRow
from spotlab.simulators.truth_npz import truth_writer

FIRMWARE = "1.0"
#: Time from the end of the sweep to the frame being queued.
ASSEMBLY_S = 50e-6
MODE_NAMES = {v: k for k, v in cw.MODES.items()}
#: Kinds of the scanner's own faults in its fault log (beside the link faults).
SCANNER_FAULT_KINDS = ("colour", "alias", "ghost")


@dataclass
class CodaConfig:
    """Device configuration (the spec's defaults after reset or ``INIT:``)."""

    rate_mhz: int = 300_000
    mode: int = 3
    table: list[int] = field(default_factory=list)


@dataclass(frozen=True)
class CodaFaults:
    """Rates of the scanner's own faults and its surroundings.

    Attributes
    ----------
    colour : float
        Probability a detection's colour bands are misread (per marker and scan).
    ghost : float
        Probability of a reflection of a marker in the back wall (per marker and scan).
    occlusion : float
        Probability a marker becomes hidden from one mirror (per marker, mirror and
        scan); an occlusion lasts 30 scans on average.
    ambient : float
        Ambient light, 0-1: angle noise times ``1 + 4 ambient``; above 0.5 the status
        word's ambient bit is set.
    """

    colour: float = 0.001
    ghost: float = 0.0005
    occlusion: float = 0.001
    ambient: float = 0.0


class CodaStream(Mcs1Stream):
    """The scans of one ``START:`` .. ``STOP:`` period."""

    def __init__(self, device: CodaDevice, config: CodaConfig, start_ns: int, index: int):
        self.device = device
        self.cconfig = config
        self._hidden = np.zeros((cw.MAX_MARKERS + 1, 3), dtype=np.int64)
        self._aliased: dict[int, FaultEntry] = {}
        self.sweep_s = scene.SWEEP_FRACTION * 1000.0 / config.rate_mhz
        super().__init__(device.clock, index, config.rate_mhz, start_ns)

    def _ready_osc(self, osc0: float) -> float:
        return osc0 + self.sweep_s + ASSEMBLY_S

    def _occlusion(self, ids: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """(N, 3) True where mirror j cannot see marker i this scan."""
        p = self.device.fault_rates.occlusion
        hidden = self._hidden[ids]
        start = (hidden == 0) & (rng.random(hidden.shape) < p)
        hidden = np.where(start, rng.geometric(1 / 30, hidden.shape), hidden)
        self._hidden[ids] = np.maximum(hidden - 1, 0)
        return hidden > 0

    def _detect(
        self, ids: np.ndarray, t0_s: float, rng: np.random.Generator, ghost: bool
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """counts (N, 3), dt µs (N, 3), xyz 0.01 mm (N, 3), flags (N,) of markers ``ids``."""
        dev = self.device
        cr = scene.crossings(ids, t0_s, self.sweep_s, dev.base_mm, ghost=ghost, pose=dev.pose)
        r = np.linalg.norm(cr.positions[:, 0], axis=-1)
        counts = scene.measure(cr.angles, r, dev.fault_rates.ambient, rng)
        if not ghost:
            counts[self._occlusion(ids, rng)] = cw.NOT_SEEN
        seen = counts != cw.NOT_SEEN
        sweep_us = self.sweep_s * 1e6
        dt = np.where(seen, np.floor(sweep_us * counts / cw.COUNTS), cw.NOT_SEEN).astype(np.int64)
        xyz, valid = scene.device_xyz(counts, dev.base_mm)
        flags = (
            valid * cw.F_3D_VALID
            + seen[:, 0] * cw.F_SEEN_A
            + seen[:, 1] * cw.F_SEEN_B
            + seen[:, 2] * cw.F_SEEN_C
        )
        return counts, dt, np.rint(xyz * 100).astype(np.int64), flags.astype(np.int64)

    def take(self) -> TakenFrame:
        """Scan, build the records, write the truth, schedule the next scan."""
        dev, cfg = self.device, self.cconfig
        rng = np.random.default_rng([dev.scene_seed, self.index, self.frame_no])
        w0 = float(self.clock.world_ns(self._osc0))
        t0_s = w0 / 1e9  # world time: every simulated unit on the machine sees one scene
        limit = cw.marker_limit(cfg.rate_mhz)
        table = np.asarray(cfg.table, dtype=np.int64)
        entry = np.arange(table.shape[0])
        in_scene = (table <= dev.scene_markers) | (
            dev.reference & np.isin(table, list(scene.REFERENCE))
        )
        ids, entries = table[in_scene], entry[in_scene]
        records: list[cw.MarkerRecord] = []
        faults: list[tuple[str, int, int]] = []  # (kind, true ID, ID reported) per record
        if ids.shape[0]:
            counts, dt, xyz, flags = self._detect(ids, t0_s, rng, ghost=False)
            slot = entries % limit
            shared = np.bincount(entry % limit, minlength=limit)[slot] > 1
            report = ids.copy()
            report[shared] = table[slot[shared]]  # the slot's lowest entry
            flags[shared] |= cw.F_ALIASED
            misread = (rng.random(ids.shape[0]) < dev.fault_rates.colour) & ~shared
            other = (report - 1 + rng.integers(1, cw.MAX_MARKERS, ids.shape[0])) % 56 + 1
            report[misread] = other[misread]
            flags[misread] |= cw.F_COLOUR_AMBIGUOUS
            for i in np.flatnonzero((flags & 0x0E) != 0).tolist():
                records.append(cw.MarkerRecord(
                    int(report[i]), int(flags[i]), tuple(xyz[i].tolist()),
                    tuple(counts[i].tolist()), tuple(dt[i].tolist()),
                ))  # fmt: skip
                kind = "alias" if shared[i] else "colour" if misread[i] else ""
                faults.append((kind, int(ids[i]), int(report[i])))
            ghosts = ids[rng.random(ids.shape[0]) < dev.fault_rates.ghost]
            if ghosts.shape[0]:
                g_counts, g_dt, g_xyz, g_flags = self._detect(ghosts, t0_s, rng, ghost=True)
                for i in np.flatnonzero((g_flags & 0x0E) != 0).tolist():
                    records.append(cw.MarkerRecord(
                        int(ghosts[i]), int(g_flags[i]) | cw.F_GHOST, tuple(g_xyz[i].tolist()),
                        tuple(g_counts[i].tolist()), tuple(g_dt[i].tolist()),
                    ))  # fmt: skip
                    faults.append(("ghost", int(ghosts[i]), int(ghosts[i])))
        slots = table.shape[0] + cw.SPARE_SLOTS
        self._log_faults(faults[:slots], int(w0))
        records = sorted(records[:slots], key=lambda r: (r.marker_id, r.flags))
        payload = cw.csx_payload(
            self.frame_no, self._tick, 0, cfg.mode, table.shape[0], limit, records
        )
        scene_ids = np.arange(1, dev.scene_markers + 1)
        truth = TruthRow(
            stream=self.index, frame_no=self.frame_no, world_ns=w0, device_us=self._tick,
            led_ids=scene_ids, positions=scene.marker_positions(scene_ids, np.asarray(t0_s)),
        )  # fmt: skip
        return self._finish(payload, truth, ambient_high=dev.fault_rates.ambient > 0.5)

    def _log_faults(self, faults: list[tuple[str, int, int]], world_ns: int) -> None:
        """Enter the scanner's own faults of this scan in the device's fault log.

        A colour misreading or a ghost is one entry (``detail``: the marker, the ID
        reported); an aliased marker is one entry per ``START:`` whose ``detail["scans"]``
        counts the scans it was reported in under another entry's ID.
        """
        log = self.device.fault_log
        t_s = self.device.faults.since_start(world_ns)
        for kind, marker, reported in faults:
            if not kind:
                continue
            if kind == "alias":
                entry = self._aliased.get(marker)
                if entry is None:
                    entry = self._aliased[marker] = log.new(kind, t_s, world_ns, "device", None)
                    entry.frame_no.append(self.frame_no)
                    entry.detail = {"marker": marker, "reported": reported, "scans": 0}
                entry.detail["scans"] += 1
                continue
            entry = log.new(kind, t_s, world_ns, "device", None)
            entry.frame_no.append(self.frame_no)
            entry.detail = {"marker": marker, "reported": reported}

    def _frame(self, seq: int, payload: bytes, flags: int) -> bytes:
        return cw.csx_frame(seq, payload, flags)


class CodaDevice(Mcs1Device[CodaConfig]):
    """A CSX scanner as seen from its serial port.

    Parameters
    ----------
    clock : DeviceClock, optional
        The unit's clock.
    faults : FaultInjector, optional
        Link faults to inject.
    scene_markers : int
        Markers in the scene, IDs 1..N (1-56); table entries beyond are never seen.
    base_mm : float
        The mirror base (reported in ``VER:0``).
    fault_rates : CodaFaults, optional
        The scanner's own faults and ambient light.
    pose : Pose, optional
        Where the unit stands in the world (default: the origin, looking along +y).
    reference : bool
        The static reference object of :data:`~spotlab.simulators.coda_scene.REFERENCE`
        (IDs 50-53) is in the scene too.
    serial : str
        Serial number in the ``VER:0`` reply.
    seed : int
        Seed of the scene's noise and faults and of line garbling.
    truth : path, optional
        Frame truth: CSV, or ``.npz`` arrays for that suffix
        (:mod:`~spotlab.simulators.truth_npz`).
    fault_log : path, optional
        JSON fault log: the link faults and the scanner's own
        (:data:`SCANNER_FAULT_KINDS`, :meth:`CodaStream._log_faults`).
    default_rate_hz : float
        Scan rate after reset or ``INIT:`` (coda.md: 300 Hz).
    now_ns : int, optional
        World time of power-up.
    lab : LabPublisher, optional
        Where the scan pulses are published (a timer's inputs can be wired to them).
    """

    RATE_RANGE_MHZ = (50_000, 800_000)

    def __init__(
        self,
        clock: DeviceClock | None = None,
        faults: FaultInjector | None = None,
        *,
        scene_markers: int = 8,
        base_mm: float = 1000.0,
        fault_rates: CodaFaults | None = None,
        pose: scene.Pose | None = None,
        reference: bool = False,
        serial: str = "SIM00031",
        seed: int = 0,
        truth: str | Path | None = None,
        fault_log: str | Path | None = None,
        default_rate_hz: float = 300.0,
        now_ns: int | None = None,
        lab: LabPublisher | None = None,
    ) -> None:
        if not 1 <= scene_markers <= cw.MAX_MARKERS:
            raise ValueError(f"scene markers must be 1-{cw.MAX_MARKERS}, got {scene_markers}")
        if not 100.0 <= base_mm <= 5000.0:
            raise ValueError(f"the mirror base must be 100-5000 mm, got {base_mm}")
        self.scene_markers = scene_markers
        self.base_mm = float(base_mm)
        self.fault_rates = fault_rates if fault_rates is not None else CodaFaults()
        self.pose = pose if pose is not None else scene.Pose()
        self.reference = bool(reference)
        self.scene_seed = int(seed)
        super().__init__(
            clock, faults, serial=serial, seed=seed,
            truth=truth_writer(truth, scene_markers + 1) if truth is not None else None,
            fault_log=fault_log, default_rate_hz=default_rate_hz, now_ns=now_ns, lab=lab,
        )  # fmt: skip

    # -- MCS-1 hooks ---------------------------------------------------------------
    def _default_config(self) -> CodaConfig:
        return CodaConfig(rate_mhz=self._default_rate_mhz)

    def version_text(self) -> str:
        """``CSX <firmware> <serial> <base µm> <counts> <field m°>``."""
        base_um = round(self.base_mm * 1000)
        return f"CSX {FIRMWARE} {self.serial} {base_um} {cw.COUNTS} {round(cw.FOV_DEG * 1000)}"

    def _family_handlers(self) -> dict[str, Handler]:
        return {"MARK": self._csx_mark, "OUT": self._csx_out, "CONF": self._csx_conf}

    def _check_start(self) -> None:
        cfg = self._config
        if not cfg.table:
            raise CommandError(0x82)
        if cfg.rate_mhz * cw.csx_frame_length(len(cfg.table), cfg.mode) * 10 > 800 * self._baud:
            raise CommandError(0x80)

    def _new_stream(self, t: int, index: int) -> Mcs1Stream:
        cfg = self._config
        return CodaStream(self, CodaConfig(cfg.rate_mhz, cfg.mode, list(cfg.table)), t, index)

    # -- CSX verbs -----------------------------------------------------------------
    def _csx_conf(self, cmd: Command, t: int) -> str:
        """The configuration in force, as the commands that set it (coda.md §3)."""
        self._no_params(cmd)
        c = self._config
        text = f"CONF RATE={c.rate_mhz} OUT={MODE_NAMES[c.mode]}"
        if c.table:
            text += " MARK=" + ",".join(cw.id_colour(i) for i in c.table)
        return text

    def _csx_mark(self, cmd: Command, t: int) -> str:
        self._not_streaming()
        codes = [p for p in cmd.params if p]
        if not codes:
            raise CommandError(0x07)
        try:
            ids = [cw.colour_id(c) for c in codes]
        except ValueError:
            raise CommandError(0x81) from None
        if len(set(ids)) != len(ids) or len(ids) > cw.MAX_MARKERS:
            raise CommandError(0x81)
        self._config.table = ids
        return self._configured()

    def _csx_out(self, cmd: Command, t: int) -> str:
        self._not_streaming()
        if len(cmd.params) != 1:
            raise CommandError(0x07)
        if cmd.params[0] not in cw.MODES:
            raise CommandError(0x23)
        self._config.mode = cw.MODES[cmd.params[0]]
        return self._configured()
