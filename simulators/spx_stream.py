"""One SPX stream: the frame schedule, sampling the scene per slot, AGC (selspot.md §2-4).

Frame ``k`` of a stream starts at oscillator time ``start + k / rate``. Its
tick is the device counter at that instant, rounded to whole µs, and the true
start is moved by the rounding so that tick and truth agree exactly (before
trigger jitter). LED ``k`` of the table is sampled at ``tick + (k + 1/2) slot``;
with ``BGND:1`` its dark sample is taken at ``tick + (k + 1/5) slot`` in the same
slot, with ``BGND:2`` all LEDs share the dark slot ``N`` at
``tick + (N + 1/2) slot``. The frame is complete, and queued for sending, one
slot after its last (LED or dark) slot: ``tick + (N + 1 + b) slot``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from spotlab.simulators import wire
from spotlab.simulators.clock import DeviceClock
from spotlab.simulators.mcs1_stream import Mcs1Stream, TakenFrame
from spotlab.simulators.psd import PsdModel, PsdReading
from spotlab.simulators.scene import Scene
from spotlab.simulators.truth import TruthRow

I64 = npt.NDArray[np.int64]
F64 = npt.NDArray[np.float64]
B = npt.NDArray[np.bool_]

MA_PER_STEP = 0.25


@dataclass
class SpxConfig:
    """Device configuration (defaults are the spec's, after reset or ``INIT:``)."""

    cameras: int = 1
    table: list[tuple[int, int]] = field(default_factory=list)
    slot_us: int = 100
    rate_mhz: int = 100_000
    bgnd: int = 1
    agc_on: bool = False
    agc_target: int = 160

    def dark_slots(self) -> int:
        """``b``: 1 with one dark slot per frame (``BGND:2``), else 0."""
        return 1 if self.bgnd == 2 else 0

    def timing_ok(self) -> bool:
        """``1/rate >= (N + 1 + b) * slot``, in integers."""
        n = len(self.table)
        return 1_000_000_000 >= (n + 1 + self.dark_slots()) * self.slot_us * self.rate_mhz

    def bandwidth_ok(self, baud: int) -> bool:
        """``rate * (28 + 5 N C) * 10 <= 0.8 * baud``, in integers (rate in mHz)."""
        frame = wire.spx_frame_length(len(self.table), self.cameras)
        return self.rate_mhz * frame * 10 <= 800 * baud


class SpxStream(Mcs1Stream):
    """Frames of one ``START:`` .. ``STOP:`` period.

    Parameters
    ----------
    config : SpxConfig
        Frozen for the stream's life (configuration is refused while streaming).
    scene, clock, psd : the world, the device's clock and its detectors.
    start_ns : int
        World time the stream starts (``START:`` received).
    index : int
        Stream number since power-up (0 first).
    rng : numpy.random.Generator
        Detector noise.
    """

    def __init__(
        self,
        config: SpxConfig,
        scene: Scene,
        clock: DeviceClock,
        psd: PsdModel,
        start_ns: int,
        index: int,
        rng: np.random.Generator,
    ) -> None:
        self.config = config
        self.scene, self.psd, self.rng = scene, psd, rng
        self.ids = np.array([i for i, _ in config.table], dtype=np.int64)
        self.current = np.array([c for _, c in config.table], dtype=np.int64)
        self.agc_limit = np.zeros(self.ids.size, dtype=bool)
        self.n = self.ids.size
        self.cams = config.cameras
        self.slot_s = config.slot_us * 1e-6
        super().__init__(clock, index, config.rate_mhz, start_ns)

    def _ready_osc(self, osc0: float) -> float:
        """One slot after the last (LED or dark) slot."""
        return osc0 + (self.n + 1 + self.config.dark_slots()) * self.slot_s

    def take(self) -> TakenFrame:
        """Sample the scene for the frame that is ready now, run AGC, schedule the next one."""
        cfg, n = self.config, self.n
        jitter_ns = self.clock.jitter_for(self.index, self.frame_no) * 1e9
        k = np.arange(n, dtype=np.float64)
        slot_osc = self._osc0 + (k + 0.5) * self.slot_s
        epoch = self.clock.epoch_ns
        t_on = (self.clock.world_ns(slot_osc) + jitter_ns - epoch) * 1e-9
        positions = self.scene.positions(t_on, self.ids)
        c = min(self.cams, self.scene.n_cameras)
        spots = self.scene.spots(positions, t_on, self.ids).cameras(c)
        amb_on = self.scene.ambient_level(t_on)[:, :c]
        amb_dark = None
        if cfg.bgnd:
            dark_osc = (
                self._osc0 + (k + 0.2) * self.slot_s
                if cfg.bgnd == 1
                else np.full(n, self._osc0 + (n + 0.5) * self.slot_s)
            )
            t_dark = (self.clock.world_ns(dark_osc) - epoch) * 1e-9
            amb_dark = self.scene.ambient_level(t_dark)[:, :c]
        reading = self.psd.measure(
            spots,
            self.current * MA_PER_STEP,
            amb_on,
            amb_dark,
            self.rng,
            self.scene.ambient.centroid,
        )
        if c < self.cams:
            reading = _with_absent_cameras(reading, self.cams - c)
        reading.flags |= np.where(self.agc_limit[:, None], wire.FLAG_AGC_LIMIT, 0).astype(np.uint8)
        truth = TruthRow(
            stream=self.index,
            frame_no=self.frame_no,
            world_ns=float(self.clock.world_ns(self._osc0)) + jitter_ns,
            device_us=self._tick,
            led_ids=self.ids,
            positions=positions,
        )
        payload = wire.spx_payload(
            self.frame_no, self._tick, 0, cfg.slot_us, reading.x, reading.y, reading.intensity,
            reading.flags,
        )  # fmt: skip
        ambient_high = bool(np.any(reading.flags & wire.FLAG_AMBIENT_HIGH))
        if cfg.agc_on:
            self._agc(reading)
        return self._finish(payload, truth, ambient_high)

    def _agc(self, reading: PsdReading) -> None:
        """Per LED, steer the drive current so that the brightest valid camera nears the target."""
        valid = (reading.flags & wire.FLAG_VALID) != 0
        level = np.where(valid, reading.intensity.astype(np.int64), -1).max(axis=1)
        seen = level >= 0
        target = self.config.agc_target
        step = np.maximum(1, self.current // 8)
        down = seen & (level > 1.25 * target)
        up = seen & (level < 0.75 * target)
        wanted = self.current - np.where(down, step, 0) + np.where(up, step, 0)
        new = np.clip(wanted, 1, 255)
        # At a clamp while still out of the band: the clamp swallowed the change.
        self.agc_limit = new != wanted
        self.current = new

    def _frame(self, seq: int, payload: bytes, flags: int) -> bytes:
        return wire.frame(wire.FRAME_SPX, seq, payload, flags)

    def led_query(self) -> str:
        """``LEDQ`` entries: the table with the drive currents in force now."""
        return "".join(
            f"{i:02X}{c:02X}" for i, c in zip(self.ids.tolist(), self.current.tolist(), strict=True)
        )


def _with_absent_cameras(reading: PsdReading, n: int) -> PsdReading:
    """Append ``n`` cameras that are not connected: no light, so invalid and low signal."""
    rows = reading.x.shape[0]

    def pad(a: npt.NDArray[np.generic], value: float) -> npt.NDArray[np.generic]:
        return np.concatenate([a, np.full((rows, n), value, dtype=a.dtype)], axis=1)

    return PsdReading(
        x=pad(reading.x, wire.INVALID),
        y=pad(reading.y, wire.INVALID),
        intensity=pad(reading.intensity, 0),
        flags=pad(reading.flags, wire.FLAG_LOW_SIGNAL),
        power=pad(reading.power, 0.0),
    )
