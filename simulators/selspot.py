"""Byte-level emulator of the SPX lateral-photodiode camera system (docs/protocols/selspot.md).

:class:`SelspotDevice` is an MCS-1 device (:class:`~spotlab.simulators.mcs1_device.Mcs1Device`:
event loop, line pacing, link faults, FIFO, truth, lab) with the SPX command
table (selspot.md §2) and :class:`~spotlab.simulators.spx_stream.SpxStream`:
cameras of lateral photodiodes looking at a :class:`Scene` of LEDs.

The order of the checks follows the spec: ``0C`` (streaming) first, then
``07`` (parameter count), then the values (``23``, ``81``); ``START:`` checks
``82``, timing (``23``), bandwidth (``80``).

Nothing here imports the driver: the device side is written from the spec.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from spotlab.simulators import wire
from spotlab.simulators.clock import DeviceClock
from spotlab.simulators.commands import Command, CommandError
from spotlab.simulators.faults import FaultInjector
from spotlab.simulators.lab import LabPublisher
from spotlab.simulators.mcs1_commands import Handler
from spotlab.simulators.mcs1_device import FIFO_BYTES, Mcs1Device
from spotlab.simulators.mcs1_stream import Mcs1Stream
from spotlab.simulators.psd import PsdModel
from spotlab.simulators.scene import Scene
from spotlab.simulators.spx_stream import SpxConfig, SpxStream
from spotlab.simulators.truth import TruthWriter

FIRMWARE = "1.0"
MAX_CAMERAS = 4
MAX_LEDS = 128
_HEX = frozenset("0123456789ABCDEFabcdef")


class SelspotDevice(Mcs1Device[SpxConfig]):
    """An SPX camera system as seen from its serial port.

    Parameters
    ----------
    scene : Scene
        What the cameras look at; its camera count is the device's maximum.
    seed : int
        Seed of the detector noise and of line garbling.
    psd : PsdModel, optional
        Detector parameters.
    truth : path, optional
        Ground-truth CSV to write (see :mod:`spotlab.simulators.truth`).
    clock, faults, serial, fault_log, default_rate_hz, fifo_bytes, mark_simulated, now_ns, lab :
        As :class:`~spotlab.simulators.mcs1_device.Mcs1Device` (the spec's
        default frame rate is 100 Hz).
    """

    def __init__(
        self,
        scene: Scene,
        clock: DeviceClock | None = None,
        faults: FaultInjector | None = None,
        *,
        serial: str = "SIM00042",
        seed: int = 0,
        psd: PsdModel | None = None,
        truth: str | Path | None = None,
        fault_log: str | Path | None = None,
        default_rate_hz: float = 100.0,
        fifo_bytes: int = FIFO_BYTES,
        mark_simulated: bool = True,
        now_ns: int | None = None,
        lab: LabPublisher | None = None,
    ) -> None:
        self.scene = scene
        self.psd = psd if psd is not None else PsdModel()
        super().__init__(
            clock, faults, serial=serial, seed=seed,
            truth=TruthWriter(truth, scene.n_leds) if truth is not None else None,
            fault_log=fault_log, default_rate_hz=default_rate_hz, fifo_bytes=fifo_bytes,
            mark_simulated=mark_simulated, now_ns=now_ns, lab=lab,
        )  # fmt: skip
        self._noise_rng = np.random.default_rng(self.noise_seed)

    # ------------------------------------------------------------ MCS-1 hooks
    def _default_config(self) -> SpxConfig:
        return SpxConfig(rate_mhz=self._default_rate_mhz)

    def version_text(self) -> str:
        """``SPX <firmware> <serial> <cameras> <LEDs>``."""
        return f"SPX {FIRMWARE} {self.serial} {MAX_CAMERAS} {MAX_LEDS}"

    def _family_handlers(self) -> dict[str, Handler]:
        return {
            "CAMS": self._cmd_cams, "LEDT": self._cmd_ledt, "LEDQ": self._cmd_ledq,
            "SLOT": self._cmd_slot, "BGND": self._cmd_bgnd, "AGC": self._cmd_agc,
            "CONF": self._cmd_conf,
        }  # fmt: skip

    def _check_start(self) -> None:
        cfg = self._config
        if not cfg.table:
            raise CommandError(0x82)
        if not cfg.timing_ok():
            raise CommandError(0x23)
        if not cfg.bandwidth_ok(self._baud):
            raise CommandError(0x80)

    def _new_stream(self, t: int, index: int) -> Mcs1Stream:
        cfg = SpxConfig(**{**self._config.__dict__, "table": list(self._config.table)})
        return SpxStream(cfg, self.scene, self.clock, self.psd, t, index, self._noise_rng)

    def _status_now(self, t: int) -> int:
        """The ambient-light bit when a detector sees more ambient light than it copes with."""
        scene_s = (t - self.clock.epoch_ns) * 1e-9
        if np.any(self.scene.ambient_level(np.array([scene_s])) > self.psd.ambient_high):
            return wire.STATUS_AMBIENT_HIGH
        return 0

    def _stream_stopping(self, stream: Mcs1Stream) -> None:
        # AGC's currents stay in force after the stream (LEDQ reports them).
        assert isinstance(stream, SpxStream)
        self._config.table = list(zip(stream.ids.tolist(), stream.current.tolist(), strict=True))

    # -------------------------------------------------------------- SPX verbs
    def _cmd_cams(self, cmd: Command, t: int) -> str:
        self._not_streaming()
        # 1-4 whatever the rig: cameras that are not connected read nothing.
        self._config.cameras = self._int_param(cmd, 1, MAX_CAMERAS)
        return self._configured()

    def _cmd_slot(self, cmd: Command, t: int) -> str:
        self._not_streaming()
        self._config.slot_us = self._int_param(cmd, 50, 1000)
        return self._configured()

    def _cmd_bgnd(self, cmd: Command, t: int) -> str:
        self._not_streaming()
        self._config.bgnd = self._int_param(cmd, 0, 2)
        return self._configured()

    def _cmd_agc(self, cmd: Command, t: int) -> str:
        self._not_streaming()
        on = self._int_param(cmd, 0, 1, count=2, index=0)
        target = self._int_param(cmd, 1, 255, count=2, index=1)
        self._config.agc_on, self._config.agc_target = bool(on), target
        return self._configured()

    def _cmd_ledt(self, cmd: Command, t: int) -> str:
        self._not_streaming()
        text = ",".join(cmd.params)
        if not text or len(text) % 4 or not set(text) <= _HEX or len(text) // 4 > MAX_LEDS:
            raise CommandError(0x81)
        table = [
            (int(text[i : i + 2], 16), int(text[i + 2 : i + 4], 16)) for i in range(0, len(text), 4)
        ]
        ids = [i for i, _ in table]
        if max(ids) > 0x7F or len(set(ids)) != len(ids):
            raise CommandError(0x81)
        self._config.table = table
        return self._configured()

    def _cmd_ledq(self, cmd: Command, t: int) -> str:
        self._no_params(cmd)
        if self._stream is not None:
            assert isinstance(self._stream, SpxStream)
            return f"LEDQ {self._stream.led_query()}"
        if not self._config.table:
            raise CommandError(0x82)
        return "LEDQ " + "".join(f"{i:02X}{c:02X}" for i, c in self._config.table)

    def _cmd_conf(self, cmd: Command, t: int) -> str:
        """The configuration in force, as the commands that set it (mcs1.md §3)."""
        self._no_params(cmd)
        c = self._config
        words = [
            f"RATE={c.rate_mhz}", f"CAMS={c.cameras}", f"SLOT={c.slot_us}", f"BGND={c.bgnd}",
            f"AGC={int(c.agc_on)},{c.agc_target}",
        ]  # fmt: skip
        if c.table:
            words.append("LEDT=" + "".join(f"{i:02X}{cur:02X}" for i, cur in c.table))
        return "CONF " + " ".join(words)
