"""Byte-level emulator of the TMR timer/sync unit (docs/protocols/timer.md).

:class:`TimerDevice` is an MCS-1 device
(:class:`~spotlab.simulators.mcs1_device.Mcs1Device`: event loop, line pacing,
fault injection, FIFO, truth and fault log) with the TMR command table and
:class:`TimerStream`, which carries edges instead of a scene. Its
inputs are wired to other simulators' frame pulses through the lab folder
(:mod:`spotlab.simulators.lab`): input ``i`` wired to ``name`` captures an edge
at the true world instant of each of that device's frame pulses, stamped with
the timer's own counter (its :class:`DeviceClock`, plus capture jitter).

Truth: the frame truth CSV has one row per timer frame (columns of
:mod:`spotlab.simulators.truth`; ``device_us`` is the counter / 10, the frame
starts on a whole µs). The edge truth CSV (``<truth>.edges.csv`` unless named)
has one row per captured edge or emitted pulse: ``channel, edge_index, rising,
true_time_s, timer_tick, source, source_stream, source_frame_no,
timer_frame_no`` (-1 when the edge was dropped for lack of room). Join
``(source_stream, source_frame_no)`` with the source's truth ``(stream,
frame_no)`` to get its ``seq``.

Nothing here imports the driver: the device side is written from the spec.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from spotlab.simulators import timer_wire as tw
from spotlab.simulators import wire
from spotlab.simulators.clock import DeviceClock
from spotlab.simulators.commands import Command, CommandError
from spotlab.simulators.faults import FaultEntry, FaultInjector
from spotlab.simulators.lab import PulseSource
from spotlab.simulators.mcs1_commands import Handler
from spotlab.simulators.mcs1_device import Mcs1Device
from spotlab.simulators.mcs1_stream import Mcs1Stream, TakenFrame
from spotlab.simulators.truth import TruthRow, TruthWriter

FIRMWARE = "1.0"
#: Time from a frame's instant to the moment it is queued for sending.
ASSEMBLY_S = 20e-6
#: Records waiting beyond this many frames' worth of slots are dropped.
BACKLOG_FRAMES = 4
EDGE_COLUMNS = (
    "channel,edge_index,rising,true_time_s,timer_tick,source,source_stream,source_frame_no,"
    "timer_frame_no"
)


@dataclass
class TimerConfig:
    """Device configuration (the spec's defaults after reset or ``INIT:``)."""

    rate_mhz: int = 100_000
    slots: int = 8
    timecode: tuple[int, bool] | None = None


@dataclass
class _Pending:
    record: tw.EdgeRecord
    world_ns: float
    source: str
    source_stream: int
    source_frame_no: int


class EdgeTruthWriter:
    """CSV of every captured edge and emitted pulse (see the module docstring)."""

    def __init__(self, path: str | Path, flush_every: int = 200) -> None:
        self.path = Path(path)
        self.flush_every = flush_every
        self._lines: list[str] = []
        self.path.write_text(EDGE_COLUMNS + "\n", encoding="ascii")

    def add(self, p: _Pending, timer_frame_no: int) -> None:
        r = p.record
        self._lines.append(
            f"{r.channel},{r.count},{int(r.rising)},{p.world_ns / 1e9:.9f},{r.tick},"
            f"{p.source},{p.source_stream},{p.source_frame_no},{timer_frame_no}\n"
        )
        if len(self._lines) >= self.flush_every:
            self.flush()

    def flush(self) -> None:
        if self._lines:
            with open(self.path, "a", encoding="ascii") as fh:
                fh.write("".join(self._lines))
            self._lines.clear()


class TimerStream(Mcs1Stream):
    """Timer frames of one ``START:`` .. ``STOP:`` period, with the edges they carry.

    Frame ``k`` starts on the whole µs nearest oscillator time ``start + k / rate``
    (:func:`~spotlab.simulators.lab.frame_start`) and is queued ``ASSEMBLY_S``
    later, carrying every edge up to its instant that is not yet reported.
    """

    def __init__(self, device: TimerDevice, config: TimerConfig, start_ns: int, index: int):
        self.device = device
        self.tconfig = config
        self.counts: dict[int, int] = {}
        self.queue: deque[_Pending] = deque()
        self.edges_lost = 0
        self._prev_tick: int | None = None
        self._done: dict[tuple[int, str, int], float] = {}
        super().__init__(device.clock, index, config.rate_mhz, start_ns)

    def _ready_osc(self, osc0: float) -> float:
        return osc0 + ASSEMBLY_S

    def counter_at(self, world_ns: float, jitter_s: float = 0.0) -> int:
        """The timer counter (10 MHz ticks) at world ``world_ns``, with capture jitter."""
        us = self.clock.device_us_at_osc(self.clock.osc_s(world_ns))
        return math.floor(us * tw.TICKS_PER_US + jitter_s * tw.TICK_HZ + 1e-6)

    def _capture(self, w_frame: float) -> list[_Pending]:
        """Edges of the wired inputs up to ``w_frame`` not yet captured, in time order."""
        dev = self.device
        found: list[_Pending] = []
        for channel, source in dev.wiring.items():
            source.refresh()
            for s in source.streams:
                key = (channel, source.name, int(s["index"]))
                # Frame 0 may start a hair before START: (its tick is rounded to a whole µs).
                first = int(s["start_ns"]) - float(s["period_s"]) * 1e9
                lo = self._done.get(key, max(float(self.start_ns), first))
                for p in source.pulses(s, lo, w_frame):
                    if dev.armed_for(channel, p.rising, p.world_ns):
                        found.append(_Pending(
                            tw.EdgeRecord(0, channel, p.rising, 0), p.world_ns, source.name,
                            p.stream, p.frame_no,
                        ))  # fmt: skip
                self._done[key] = w_frame
        found.sort(key=lambda p: p.world_ns)
        return found

    def _outputs(self, tick: int) -> list[_Pending]:
        """Output pulses with counter in (previous frame, this frame]."""
        dev = self.device
        lo = self._prev_tick if self._prev_tick is not None else tick - 1
        ticks: list[tuple[int, int]] = []
        for out, (period, since) in dev.periodic.items():
            first = max(lo, since) // period + 1
            ticks += [(t, out) for t in range(first * period, tick + 1, period)]
        while dev.one_shots and dev.one_shots[0][0] <= tick:
            t, out = dev.one_shots.popleft()
            if t > lo:
                ticks.append((t, out))
        ticks.sort()
        return [
            _Pending(tw.EdgeRecord(t, tw.CHANNEL_OUTPUT | out, True, 0),
                     float(self.clock.ticks_to_world_ns(t / tw.TICKS_PER_US)), "output", -1, -1)
            for t, out in ticks
        ]  # fmt: skip

    def take(self) -> TakenFrame:
        """Capture, fill the frame's slots, write the truth, schedule the next frame."""
        dev, cfg = self.device, self.tconfig
        jitter_ns = self.clock.jitter_for(0x7173, self.index, self.frame_no) * 1e9
        w_frame = float(self.clock.world_ns(self._osc0))
        counter = self._tick * tw.TICKS_PER_US
        fresh = self._capture(w_frame)
        for p in fresh:
            count = self.counts.get(p.record.channel, 0)
            self.counts[p.record.channel] = count + 1
            jit = dev.clock.jitter_for(0xED6E, self.index, p.record.channel, count)
            tick = self.counter_at(p.world_ns, jit)
            p.record = tw.EdgeRecord(tick, p.record.channel, p.record.rising, count)
        outs = self._outputs(counter)
        for p in outs:
            count = self.counts.get(p.record.channel, 0)
            self.counts[p.record.channel] = count + 1
            p.record = tw.EdgeRecord(p.record.tick, p.record.channel, True, count)
        self.queue.extend(sorted(fresh + outs, key=lambda p: p.record.tick))
        limit = BACKLOG_FRAMES * cfg.slots
        while len(self.queue) > limit:
            lost = self.queue.pop()
            self.edges_lost += 1
            if dev.edge_truth is not None:
                dev.edge_truth.add(lost, -1)
        sent = [self.queue.popleft() for _ in range(min(cfg.slots, len(self.queue)))]
        if dev.edge_truth is not None:
            for p in sent:
                dev.edge_truth.add(p, self.frame_no)
        tc = None if cfg.timecode is None else tw.timecode_at(counter, *cfg.timecode)
        payload = tw.tmr_payload(
            self.frame_no, counter, 0, dev.armed_mask(), self.edges_lost, cfg.slots,
            [p.record for p in sent], tc,
        )  # fmt: skip
        truth = TruthRow(
            stream=self.index, frame_no=self.frame_no, world_ns=w_frame + jitter_ns,
            device_us=self._tick, led_ids=np.zeros(0, dtype=np.int64), positions=np.zeros((0, 3)),
        )  # fmt: skip
        self._prev_tick = counter
        return self._finish(payload, truth)

    def _frame(self, seq: int, payload: bytes, flags: int) -> bytes:
        return wire.frame(tw.FRAME_TMR, seq, payload, flags)


class TimerDevice(Mcs1Device[TimerConfig]):
    """A TMR timer/sync unit as seen from its serial port.

    Parameters
    ----------
    clock : DeviceClock, optional
        The unit's clock (its counter is ``10 * device_us``).
    faults : FaultInjector, optional
        Link faults to inject.
    inputs : mapping of int to PulseSource, optional
        Input number -> the lab device whose frame pulses drive it.
    serial : str
        Serial number in the ``VER:0`` reply.
    seed : int
        Seed of line garbling.
    truth, edge_truth : path, optional
        Frame truth CSV and edge truth CSV (default for the latter:
        ``<truth>.edges.csv`` when ``truth`` is given).
    fault_log : path, optional
        JSON fault log.
    default_rate_hz : float
        Frame rate after reset or ``INIT:``.
    now_ns : int, optional
        World time of power-up.
    """

    def __init__(
        self,
        clock: DeviceClock | None = None,
        faults: FaultInjector | None = None,
        *,
        inputs: Mapping[int, PulseSource] | None = None,
        serial: str = "SIM00077",
        seed: int = 0,
        truth: str | Path | None = None,
        edge_truth: str | Path | None = None,
        fault_log: str | Path | None = None,
        default_rate_hz: float = 100.0,
        now_ns: int | None = None,
    ) -> None:
        self.wiring: dict[int, PulseSource] = dict(inputs or {})
        bad = [i for i in self.wiring if not 0 <= i < tw.MAX_INPUTS]
        if bad:
            raise ValueError(f"inputs are 0-{tw.MAX_INPUTS - 1}, got {bad}")
        self._arm: dict[int, list[tuple[float, int]]] = {}
        self.periodic: dict[int, tuple[int, int]] = {}
        self.one_shots: deque[tuple[int, int]] = deque()
        if truth is not None and edge_truth is None:
            edge_truth = f"{truth}.edges.csv"
        self.edge_truth = EdgeTruthWriter(edge_truth) if edge_truth is not None else None
        super().__init__(
            clock, faults, serial=serial, seed=seed,
            truth=TruthWriter(truth, 0) if truth is not None else None, fault_log=fault_log,
            default_rate_hz=default_rate_hz, now_ns=now_ns,
        )  # fmt: skip

    # -- state the stream reads ----------------------------------------------------
    def armed_for(self, channel: int, rising: bool, world_ns: float) -> bool:
        """Was input ``channel`` armed for this polarity at ``world_ns``?"""
        mode = 0
        for t, m in self._arm.get(channel, []):
            if t > world_ns:
                break
            mode = m
        return bool(mode & (1 if rising else 2))

    def armed_mask(self) -> int:
        """The ``armed`` field: 2 bits per input, as armed now."""
        mask = 0
        for channel, changes in self._arm.items():
            if changes:
                mask |= changes[-1][1] << (2 * channel)
        return mask

    def _power_on(self, t: int, fault: FaultEntry | None) -> None:
        super()._power_on(t, fault)
        self._arm = {}
        self.periodic = {}
        self.one_shots = deque()

    def _flush_truth(self) -> None:
        super()._flush_truth()
        if self.edge_truth is not None:
            self.edge_truth.flush()

    def _close_truth(self) -> None:
        super()._close_truth()
        if self.edge_truth is not None:
            self.edge_truth.flush()

    # -- MCS-1 hooks ---------------------------------------------------------------
    def _default_config(self) -> TimerConfig:
        return TimerConfig(rate_mhz=self._default_rate_mhz)

    def version_text(self) -> str:
        """``TMR <firmware> <serial> <inputs> <outputs> <tick Hz>``."""
        return f"TMR {FIRMWARE} {self.serial} {tw.MAX_INPUTS} {tw.MAX_OUTPUTS} {tw.TICK_HZ}"

    def _family_handlers(self) -> dict[str, Handler]:
        return {
            "EDGS": self._tmr_edgs, "ARM": self._tmr_arm, "PULS": self._tmr_puls,
            "POUT": self._tmr_pout, "TCOD": self._tmr_tcod, "CONF": self._tmr_conf,
        }  # fmt: skip

    def _check_start(self) -> None:
        cfg = self._config
        if cfg.rate_mhz * tw.tmr_frame_length(cfg.slots) * 10 > 800 * self._baud:
            raise CommandError(0x80)

    def _new_stream(self, t: int, index: int) -> Mcs1Stream:
        cfg = self._config
        return TimerStream(self, TimerConfig(cfg.rate_mhz, cfg.slots, cfg.timecode), t, index)

    # -- TMR verbs -----------------------------------------------------------------
    def _tmr_conf(self, cmd: Command, t: int) -> str:
        """The configuration in force, as the commands that set it (timer.md §2)."""
        self._no_params(cmd)
        c = self._config
        tc = "0" if c.timecode is None else f"1,{c.timecode[0]},{int(c.timecode[1])}"
        return f"CONF RATE={c.rate_mhz} EDGS={c.slots} TCOD={tc}"

    def _tmr_edgs(self, cmd: Command, t: int) -> str:
        self._not_streaming()
        self._config.slots = self._int_param(cmd, 1, tw.MAX_SLOTS)
        return self._configured()

    def _tmr_tcod(self, cmd: Command, t: int) -> str:
        self._not_streaming()
        if len(cmd.params) == 1:
            self._int_param(cmd, 0, 0)
            self._config.timecode = None
            return self._configured()
        on = self._int_param(cmd, 1, 1, count=3, index=0)
        fps = self._int_param(cmd, 24, 30, count=3, index=1)
        df = self._int_param(cmd, 0, 1, count=3, index=2)
        if on != 1 or (fps, bool(df)) not in tw.FRAMES_PER_DAY:
            raise CommandError(0x23)
        self._config.timecode = (fps, bool(df))
        return self._configured()

    def _tmr_arm(self, cmd: Command, t: int) -> str:
        channel = self._int_param(cmd, 0, tw.MAX_INPUTS - 1, count=2, index=0)
        mode = self._int_param(cmd, 0, 3, count=2, index=1)
        self._arm.setdefault(channel, []).append((float(t), mode))
        return "OKAY"

    def _counter_now(self, t: int) -> int:
        return math.ceil(self.clock.device_us(t) - 1e-6) * tw.TICKS_PER_US

    def _tmr_puls(self, cmd: Command, t: int) -> str:
        out = self._int_param(cmd, 0, tw.MAX_OUTPUTS - 1)
        tick = self._counter_now(t)
        self.one_shots.append((tick, out))
        return f"PULS {tick & 0xFFFFFFFFFFFFFFFF:016X}"

    def _tmr_pout(self, cmd: Command, t: int) -> str:
        out = self._int_param(cmd, 0, tw.MAX_OUTPUTS - 1, count=2, index=0)
        period = self._int_param(cmd, 0, 10_000_000, count=2, index=1)
        if 0 < period < 100:
            raise CommandError(0x23)
        if period == 0:
            self.periodic.pop(out, None)
        else:
            self.periodic[out] = (period * tw.TICKS_PER_US, self._counter_now(t))
        return "OKAY"
