"""The SPX command table (selspot.md §2, MCS-1 §3), as a mixin of :class:`SelspotDevice`.

Each handler gets the parsed command and the world time its last byte
arrived, and returns the reply text, or None when it queued its reply itself
(``COMM:`` answers at the old rate, ``START:`` and ``STOP:`` change the stream
around their reply, ``RESET:`` answers with the banner). A refusal raises
:class:`CommandError` with the ERRORxx code. The order of the checks follows
the spec: ``0C`` (streaming) first, then ``07`` (parameter count), then the
values (``23``, ``81``); ``START:`` checks ``82``, timing (``23``), bandwidth (``80``).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from spotlab.simulators import wire
from spotlab.simulators.clock import DeviceClock
from spotlab.simulators.commands import Command, CommandError
from spotlab.simulators.faults import FaultEntry, FaultInjector, FaultLog
from spotlab.simulators.line import Chunk, TxLine
from spotlab.simulators.psd import PsdModel
from spotlab.simulators.scene import Scene
from spotlab.simulators.spx_stream import SpxConfig, SpxStream

FIRMWARE = "1.0"
MAX_CAMERAS = 4
MAX_LEDS = 128
_HEX = frozenset("0123456789ABCDEFabcdef")


class SpxCommands:
    """Handlers of every SPX verb; the device provides the state they act on."""

    scene: Scene
    clock: DeviceClock
    psd: PsdModel
    faults: FaultInjector
    line: TxLine
    serial: str
    _config: SpxConfig
    _stream: SpxStream | None
    _streams: int
    _baud: int
    _baud_switch: tuple[int, int] | None
    _stat_latch: int
    _overflow_left: int
    _default_rate_mhz: int
    _noise_rng: np.random.Generator
    _power_on: Callable[[int, FaultEntry | None], None]
    _reply: Callable[[str, int], Chunk]
    _latch: Callable[[int], None]

    @property
    def fault_log(self) -> FaultLog:
        """The exact log of injected faults."""
        return self.faults.log

    def handlers(self) -> dict[str, Callable[[Command, int], str | None]]:
        """Verb -> handler."""
        return {
            "RESET": self._cmd_reset, "INIT": self._cmd_init, "VER": self._cmd_ver,
            "COMM": self._cmd_comm, "RATE": self._cmd_rate, "START": self._cmd_start,
            "STOP": self._cmd_stop, "STAT": self._cmd_stat, "TIME": self._cmd_time,
            "CAMS": self._cmd_cams, "LEDT": self._cmd_ledt, "LEDQ": self._cmd_ledq,
            "SLOT": self._cmd_slot, "BGND": self._cmd_bgnd, "AGC": self._cmd_agc,
            "CONF": self._cmd_conf,
        }  # fmt: skip

    def _not_streaming(self) -> None:
        if self._stream is not None:
            raise CommandError(0x0C)

    @staticmethod
    def _no_params(cmd: Command) -> None:
        if cmd.params:
            raise CommandError(0x07)

    @staticmethod
    def _int_param(cmd: Command, lo: int, hi: int, count: int = 1, index: int = 0) -> int:
        if len(cmd.params) != count:
            raise CommandError(0x07)
        text = cmd.params[index]
        if not (text.isascii() and text.isdigit()) or not lo <= int(text) <= hi:
            raise CommandError(0x23)
        return int(text)

    def _configured(self) -> str:
        self._latch(wire.STATUS_CONFIG_CHANGED)
        return "OKAY"

    def _cmd_reset(self, cmd: Command, t: int) -> None:
        self._power_on(t, None)

    def _cmd_init(self, cmd: Command, t: int) -> str:
        self._not_streaming()
        self._no_params(cmd)
        self._config = SpxConfig(rate_mhz=self._default_rate_mhz)
        return self._configured()

    def _cmd_ver(self, cmd: Command, t: int) -> str:
        self._int_param(cmd, 0, 0)
        return f"SPX {FIRMWARE} {self.serial} {MAX_CAMERAS} {MAX_LEDS}"

    def _cmd_comm(self, cmd: Command, t: int) -> None:
        self._not_streaming()
        code = self._int_param(cmd, 0, 9)
        chunk = self._reply("OKAY", t)
        self._baud_switch = (chunk.end_ns, wire.BAUD_RATES[code])

    def _cmd_rate(self, cmd: Command, t: int) -> str:
        self._not_streaming()
        self._config.rate_mhz = self._int_param(cmd, 1_000, 10_000_000)
        return self._configured()

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

    def _cmd_stat(self, cmd: Command, t: int) -> str:
        self._no_params(cmd)
        status = self._stat_latch
        if np.any(self.scene.ambient_level(np.array([self._scene_s(t)])) > self.psd.ambient_high):
            status |= wire.STATUS_AMBIENT_HIGH
        self._stat_latch = 0
        return f"STAT {status:04X}"

    def _cmd_time(self, cmd: Command, t: int) -> str:
        self._no_params(cmd)
        rx = self.clock.ticks(t) & 0xFFFFFFFF
        tx = self.clock.ticks(self.line.start_time(t)) & 0xFFFFFFFF
        return f"TIME {rx:08X} {tx:08X}"

    def _cmd_start(self, cmd: Command, t: int) -> None:
        self._not_streaming()
        self._no_params(cmd)
        cfg = self._config
        if not cfg.table:
            raise CommandError(0x82)
        if not cfg.timing_ok():
            raise CommandError(0x23)
        if not cfg.bandwidth_ok(self._baud):
            raise CommandError(0x80)
        self._anchor_faults(t)
        self._reply("OKAY", t)
        stream_cfg = SpxConfig(**{**cfg.__dict__, "table": list(cfg.table)})
        self._stream = SpxStream(
            stream_cfg, self.scene, self.clock, self.psd, t, self._streams, self._noise_rng
        )
        self._streams += 1
        self._overflow_left = 0

    def _anchor_faults(self, t: int) -> None:
        """At the first ``START:``: fix the fault schedule's zero and plan the disconnects."""
        if self.faults.anchor(t):
            for spec in self.faults.timed_specs:
                if spec.kind == "disconnect" and spec.arg is not None:
                    t0 = self.faults.at_ns(spec)
                    entry = self.fault_log.new("disconnect", spec.at_s, t0, "schedule", spec.arg)
                    self.line.add_down(t0, t0 + round(spec.arg * 1e9), entry.id)

    def _cmd_stop(self, cmd: Command, t: int) -> str | None:
        self._no_params(cmd)
        if self._stream is None:
            return "OKAY"
        self._reply("OKAY", t)
        # AGC's currents stay in force after the stream (LEDQ reports them).
        self._config.table = list(
            zip(self._stream.ids.tolist(), self._stream.current.tolist(), strict=True)
        )
        self._stream = None
        return None

    def _scene_s(self, t: int) -> float:
        return (t - self.clock.epoch_ns) * 1e-9
