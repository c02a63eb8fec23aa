"""The MCS-1 device base: a simulated device as seen from its serial port (mcs1.md).

:class:`Mcs1Device` is transport-agnostic and driven by time: every call
passes the world time ``now_ns`` (``time.monotonic_ns()`` in real runs, any
increasing integer in tests) and the device catches up on everything that
happened until then, in time order — host bytes arriving (paced at the line
rate), command timeouts, frames taken on its own clock, baud switches, timed
faults. :meth:`Mcs1Device.output` returns what has left the device's
transmit line by ``now_ns``, never faster than the baud rate allows.

Everything the families share is here: the event loop, the line, the link
faults and their log, the FIFO, the truth CSV, the lab's frame pulses and the
common verbs (:class:`~spotlab.simulators.mcs1_commands.Mcs1Commands`). A
family (:class:`~spotlab.simulators.selspot.SelspotDevice`,
:class:`~spotlab.simulators.timer.TimerDevice`,
:class:`~spotlab.simulators.centroid.CentroidDevice`) adds its configuration,
its verbs and its stream (:class:`~spotlab.simulators.mcs1_stream.Mcs1Stream`);
see docs/families.md.

Nothing here imports a driver: the device side is written from the spec.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from pathlib import Path

import numpy as np

from spotlab.simulators import wire
from spotlab.simulators.clock import DeviceClock
from spotlab.simulators.commands import CommandError, LineAssembler, parse_line
from spotlab.simulators.faults import (
    GARBAGE,
    FaultEntry,
    FaultInjector,
    FaultSpec,
    drop_byte,
    flip_bit,
    truncate,
)
from spotlab.simulators.lab import LabPublisher
from spotlab.simulators.line import BIT_NS, Chunk, Outcome, Segment, TxLine
from spotlab.simulators.mcs1_commands import ConfigT, Mcs1Commands
from spotlab.simulators.mcs1_stream import Mcs1Stream, TakenFrame
from spotlab.simulators.truth import TruthRow, TruthWriter

FIFO_BYTES = 8192
_LOG_WRITE_NS = 500_000_000


class Mcs1Device(Mcs1Commands[ConfigT]):
    """An MCS-1 device as seen from its serial port; a family supplies the rest.

    A subclass sets the state its hooks read (:meth:`_default_config` first of
    all), then calls this constructor, which powers the device up.

    Parameters
    ----------
    clock : DeviceClock, optional
        The device's clock (default: ideal, powered up at ``now_ns``).
    faults : FaultInjector, optional
        Link faults to inject (default: none).
    serial : str
        Serial number in the ``VER:0`` reply.
    seed : int
        Seed of line garbling (and of :attr:`noise_seed`).
    truth : TruthWriter, optional
        Where the frames' truth rows go (see :mod:`spotlab.simulators.truth`).
    fault_log : path, optional
        JSON fault log to keep up to date (see :mod:`spotlab.simulators.faults`).
    default_rate_hz : float
        Frame rate after reset or ``INIT:`` (1 Hz to 10 kHz).
    fifo_bytes : int
        Transmit FIFO size: a frame that does not fit is dropped (FIFO overflow).
        Bytes the transport holds because the host does not read count against it
        (:attr:`host_backlog`: hardware flow control, MCS-1 §4).
    mark_simulated : bool
        Set header flag bit 2 ("simulated device") in every frame.
    now_ns : int, optional
        World time of power-up (default: ``time.monotonic_ns()``).
    lab : LabPublisher, optional
        Where to publish the frame-pulse schedule of every stream (see
        :mod:`spotlab.simulators.lab`); None: the device is in no lab.
    """

    def __init__(
        self,
        clock: DeviceClock | None = None,
        faults: FaultInjector | None = None,
        *,
        serial: str,
        seed: int = 0,
        truth: TruthWriter | None = None,
        fault_log: str | Path | None = None,
        default_rate_hz: float = 100.0,
        fifo_bytes: int = FIFO_BYTES,
        mark_simulated: bool = True,
        now_ns: int | None = None,
        lab: LabPublisher | None = None,
    ) -> None:
        now = time.monotonic_ns() if now_ns is None else int(now_ns)
        self.lab = lab
        self._running: Mcs1Stream | None = None
        rate_mhz = round(default_rate_hz * 1000)
        if not 1_000 <= rate_mhz <= 10_000_000:
            raise ValueError(f"default frame rate must be 1 Hz to 10 kHz, got {default_rate_hz}")
        self.clock = clock if clock is not None else DeviceClock(epoch_ns=now)
        self.faults = faults if faults is not None else FaultInjector()
        self.serial = serial
        self.fifo_bytes = fifo_bytes
        #: Bytes released to the transport that the host has not taken yet (the
        #: transport sets it): flow control holds them in the FIFO, so a host that
        #: falls behind sees whole frames dropped, never frames cut into CRC errors.
        self.host_backlog = 0
        #: Resets and power-ups so far, and the world ns of the latest (a transport
        #: clears the bytes it holds back).
        self.resets = 0
        self.last_reset_ns = now
        self.mark_simulated = mark_simulated
        self._default_rate_mhz = rate_mhz
        #: Seed of the family's own randomness (detector noise), apart from the line's.
        self.noise_seed, garble = np.random.SeedSequence([seed, 0x5E15]).spawn(2)
        self._garble_rng = np.random.default_rng(garble)
        self._truth = truth
        self._fault_log_path = Path(fault_log) if fault_log is not None else None
        self._lock = threading.RLock()
        self.line = TxLine(self._resolved, free_ns=now)
        self._rx: deque[tuple[int, int, int]] = deque()  # (arrival ns, byte, line baud or 0)
        self._host_free_ns = now
        self._asm = LineAssembler()
        self._now = now
        self._stream = None
        self._streams = 0
        self._overflow_left = 0
        self._drop_entry: FaultEntry | None = None
        self._log_written_ns = now
        self._closed = False
        self._baud = wire.RESET_BAUD
        self._baud_switch: tuple[int, int] | None = None
        self._config = self._default_config()
        self._frame_latch = self._stat_latch = 0
        self._resync_latch = False
        self._handlers = self.handlers()
        self._power_on(now, None)

    # ------------------------------------------------------------------ public
    @property
    def _stream(self) -> Mcs1Stream | None:
        """The running stream; setting it tells the lab (at the device's current time)."""
        return self._running

    @_stream.setter
    def _stream(self, stream: Mcs1Stream | None) -> None:
        if self.lab is not None and stream is not self._running:
            if self._running is not None:
                self.lab.stopped(self._now)
            if stream is not None:
                self.lab.started(stream.index, self._now, stream.start_osc, stream.period_s)
        self._running = stream

    @property
    def baud(self) -> int:
        """The device's line rate now."""
        return self._baud

    @property
    def streaming(self) -> bool:
        """Is a stream running?"""
        return self._stream is not None

    @property
    def config(self) -> ConfigT:
        """The configuration in force (do not modify)."""
        return self._config

    def receive(self, data: bytes, now_ns: int | None = None, line_baud: int | None = None) -> None:
        """Bytes written by the host at ``now_ns``.

        They arrive one per 10 bit times of ``line_baud`` (the host port's rate;
        None: the device's own rate, as over TCP). When ``line_baud`` differs
        from the device's rate the device receives garbage, as on a real line.
        Bytes written while the link is disconnected are lost.
        """
        with self._lock:
            now = self._advance(now_ns)
            if self.line.is_down(now) or not data:
                return
            baud = line_baud or self._baud
            t0 = max(now, self._host_free_ns)
            for i, b in enumerate(data):
                self._rx.append((t0 + ((i + 1) * BIT_NS) // baud, b, line_baud or 0))
            self._host_free_ns = self._rx[-1][0]

    def output_segments(self, now_ns: int | None = None) -> list[Segment]:
        """What left the device by ``now_ns``, as runs of bytes with the baud they were sent at."""
        with self._lock:
            now = self._advance(now_ns)
            segments = self.line.release(now)
            if self._fault_log_path is not None and now - self._log_written_ns > _LOG_WRITE_NS:
                self._write_log(now)
            return segments

    def output(self, now_ns: int | None = None) -> bytes:
        """The bytes that left the device by ``now_ns`` (and were not returned before)."""
        return b"".join(s.data for s in self.output_segments(now_ns))

    def send_break(self, now_ns: int | None = None) -> None:
        """A serial BREAK from the host: reset to 9600 baud and send the banner."""
        with self._lock:
            now = self._advance(now_ns)
            if not self.line.is_down(now):
                self._power_on(now, None)

    def next_event_ns(self) -> int | None:
        """World ns of the next thing the device will do or emit, or None when idle."""
        with self._lock:
            times = [
                self.line.next_ns(),
                self._rx[0][0] if self._rx else None,
                self._asm.deadline_ns(),
                self._stream.ready_ns if self._stream is not None else None,
                self._baud_switch[0] if self._baud_switch else None,
                self.faults.next_timed_ns(),
                self.line.transitions_after(self._now),
            ]
            due = [t for t in times if t is not None]
            return min(due) if due else None

    def link_down(self, now_ns: int | None = None) -> bool:
        """Is the port disconnected (disconnect fault) at ``now_ns``?"""
        with self._lock:
            return self.line.is_down(self._advance(now_ns))

    def link_return_ns(self, now_ns: int | None = None) -> int | None:
        """When a disconnected port comes back, or None when it is connected."""
        with self._lock:
            return self.line.down_until(self._advance(now_ns))

    def link_broken_between(self, t0_ns: int, t1_ns: int) -> bool:
        """Did the port go away at some moment in (t0_ns, t1_ns]? (An open handle then is dead.)"""
        with self._lock:
            return self.line.down_started_between(t0_ns, t1_ns)

    def host_bytes_done_ns(self) -> int:
        """World ns when the last byte written by the host will have arrived."""
        with self._lock:
            return self._host_free_ns

    def flush(self, now_ns: int | None = None) -> None:
        """Catch up to ``now_ns`` and write the resolved truth rows and the fault log."""
        with self._lock:
            now = self._advance(now_ns)
            self._flush_truth()
            self._write_log(now)

    def close(self, now_ns: int | None = None, catch_up: bool = True) -> None:
        """Catch up to ``now_ns`` (unless not ``catch_up``), finish the truth file and fault log."""
        with self._lock:
            if self._closed:
                return
            now = self._now
            if catch_up:
                now = self._advance(now_ns)
                self.line.release(now)
            self._closed = True
            if self.lab is not None and self._running is not None:
                self.lab.stopped(now)
            self._close_truth()
            self._write_log(now)

    # ----------------------------------------------------------- event loop
    def _advance(self, now_ns: int | None) -> int:
        now = max(self._now, time.monotonic_ns() if now_ns is None else int(now_ns))
        while True:
            t_baud = self._baud_switch[0] if self._baud_switch else None
            t_fault = self.faults.next_timed_ns()
            t_rx = self._rx[0][0] if self._rx else None
            t_out = self._asm.deadline_ns()
            t_frame = self._stream.ready_ns if self._stream is not None else None
            due = [
                (t, i)
                for i, t in enumerate((t_baud, t_fault, t_rx, t_out, t_frame))
                if t is not None
            ]
            if not due:
                break
            t, which = min(due)
            if t > now:
                break
            self._now = t
            if which == 0:
                assert self._baud_switch is not None
                self._baud = self._baud_switch[1]
                self._baud_switch = None
            elif which == 1:
                self._timed_fault(t)
            elif which == 2:
                self._rx_byte()
            elif which == 3:
                self._asm.clear()
                self._reply("ERROR05", t)
            else:
                self._on_frame(t)
        self._now = now
        return now

    def _rx_byte(self) -> None:
        t, byte, line_baud = self._rx.popleft()
        if self.line.is_down(t):
            return
        if line_baud and line_baud != self._baud:
            byte = int(self._garble_rng.integers(256))
            self._latch(wire.STATUS_COMM_SYNC)
        line = self._asm.feed(t, byte)
        if line:
            self._handle(line, t)

    def _handle(self, line: bytes, t: int) -> None:
        try:
            cmd = parse_line(line)
            handler = self._handlers.get(cmd.verb)
            if handler is None:
                raise CommandError(0x01)
            text = handler(cmd, t)
        except CommandError as exc:
            if exc.code == 0x04:
                self._latch(wire.STATUS_BAD_CRC)
            text = f"ERROR{exc.code:02X}"
        if text is not None:
            self._reply(text, t)

    def _reply(self, text: str, t: int) -> Chunk:
        data = wire.reply(text)
        if self._stream is not None:
            flags = wire.header_flags(simulated=self.mark_simulated)
            return self.line.enqueue(wire.event_frame(data, flags), t, self._baud, "event")
        return self.line.enqueue(data, t, self._baud, "reply")

    def _latch(self, bits: int) -> None:
        self._frame_latch |= bits
        self._stat_latch |= bits

    def _power_on(self, t: int, fault: FaultEntry | None) -> None:
        """Reset, BREAK or power-up: 9600 baud, defaults, stream stopped, banner."""
        self.line.cut(t, None if fault is None else fault.id)
        self.resets += 1  # the transport drops what flow control still held in the FIFO
        self.last_reset_ns = t
        self._stream = None
        self._overflow_left = 0
        self._asm.clear()
        self._baud = wire.RESET_BAUD
        self._baud_switch = None
        self._config = self._default_config()
        self._frame_latch = self._stat_latch = 0
        self._resync_latch = False
        if fault is not None:
            self._latch(wire.STATUS_RECOVERED)
        self.line.enqueue(wire.BANNER, t, self._baud, "banner")

    # ----------------------------------------------------------- streaming
    def _on_frame(self, t: int) -> None:
        stream = self._stream
        assert stream is not None
        taken = stream.take()
        log = self.fault_log
        log.frames_taken += 1
        if self._truth is not None:
            self._truth.add(taken.truth)
        self._resync_latch |= taken.resynced
        size = taken.frame_bytes
        got = None
        drop: FaultEntry | None = None
        if self._overflow_left > 0:
            self._overflow_left -= 1
            drop = self._drop_entry
        elif self.line.backlog(t) + self.host_backlog + size > self.fifo_bytes:
            last = self._drop_entry
            if last is None or last.kind != "fifo" or last.frame_no[-1] != taken.frame_no - 1:
                last = log.new("fifo", self.faults.since_start(t), t, "device", None)
            drop = self._drop_entry = last
        else:
            got = self.faults.next_frame_fault(t)
            if got is not None and got[0].kind == "overflow":
                spec, source = got
                drop = self._drop_entry = log.new("overflow", spec.at_s, t, source, spec.arg)
                self._overflow_left = int(spec.arg or 1) - 1
                got = None
        if drop is not None:
            drop.count("dropped_frames", -1, taken.frame_no)
            taken.truth.sent = False
            self._latch(wire.STATUS_FIFO_OVERFLOW)
            if self._truth is not None:
                self._truth.drain()
            return
        self._send_frame(stream, taken, t, got)

    def _send_frame(
        self, stream: Mcs1Stream, taken: TakenFrame, t: int, got: tuple[FaultSpec, str] | None
    ) -> None:
        status = self._frame_latch | (wire.STATUS_AMBIENT_HIGH if taken.ambient_high else 0)
        self._frame_latch = 0
        flags = wire.header_flags(
            simulated=self.mark_simulated,
            overrun=bool(status & wire.STATUS_FIFO_OVERFLOW),
            resynced=self._resync_latch,
        )
        self._resync_latch = False
        seq = stream.seq
        data = stream.encode(taken, status, flags)
        taken.truth.seq = seq
        self.fault_log.frames_sent += 1
        meta: dict[str, object] = {"seq": seq, "frame_no": taken.frame_no, "tag": taken.truth}
        if got is None:
            self.line.enqueue(data, t, self._baud, "data", **meta)
            return
        spec, source = got
        entry = self.fault_log.new(spec.kind, spec.at_s, t, source, spec.arg)
        rng = self.faults.rng
        if entry.kind in ("bitflip", "drop", "truncate"):
            damage = {"bitflip": flip_bit, "drop": drop_byte, "truncate": truncate}[entry.kind]
            data, entry.detail = damage(data, rng)
            self.line.enqueue(data, t, self._baud, "data", damaged_by=entry.id, **meta)
        elif entry.kind == "garbage":
            self.line.enqueue(GARBAGE, t, self._baud, "garbage")
            entry.garbage_bytes += len(GARBAGE)
            entry.detail = {"before_seq": seq}
            self.line.enqueue(data, t, self._baud, "data", **meta)
        elif entry.kind == "duplicate":
            entry.detail = {"copied_seq": seq}
            self.line.enqueue(data, t, self._baud, "data", **meta)
            self.line.enqueue(
                data, t, self._baud, "data", seq=seq, frame_no=taken.frame_no, duplicate_of=entry.id
            )
        else:  # burst
            chunk = self.line.enqueue(data, t, self._baud, "data", **meta)
            span = round((entry.arg or 0.016) * 1e9)
            entry.detail = {"t0_ns": chunk.start_ns, "t1_ns": chunk.start_ns + span}
            self.line.add_burst(chunk.start_ns, chunk.start_ns + span, entry.id, rng)

    def _timed_fault(self, t: int) -> None:
        spec = self.faults.pop_timed()
        if spec.kind == "reset":
            entry = self.fault_log.new("reset", spec.at_s, t, "schedule", None)
            self._power_on(t, entry)
            self._write_log(t)

    # ---------------------------------------------------------- accounting
    def _flush_truth(self) -> None:
        """Write what the truth files hold so far (a family adds its own files)."""
        if self._truth is not None:
            self._truth.flush()

    def _close_truth(self) -> None:
        """Finish the truth files (once, on close; a family adds its own files)."""
        if self._truth is not None:
            self._truth.close()

    def _resolved(self, chunk: Chunk, outcome: Outcome) -> None:
        """Book a chunk that has fully left the line or was thrown away."""
        entries = self.fault_log.entries
        if chunk.kind == "data":
            copy = chunk.duplicate_of is not None
            if isinstance(chunk.tag, TruthRow):
                chunk.tag.sent = outcome != "discarded"
            if outcome in ("discarded", "cut"):
                if not copy and chunk.cut_by is not None and chunk.cut_by >= 0:
                    entries[chunk.cut_by].count("discarded_frames", chunk.seq, chunk.frame_no)
            elif outcome == "lost":
                if not copy and chunk.lost_by is not None:
                    entries[chunk.lost_by].count("lost_frames", chunk.seq, chunk.frame_no)
            elif outcome == "damaged" and chunk.damaged_by is not None:
                entries[chunk.damaged_by].count("corrupted_frames", chunk.seq, chunk.frame_no)
            elif copy and chunk.duplicate_of is not None:
                entries[chunk.duplicate_of].count("duplicated_frames", chunk.seq, chunk.frame_no)
            if self._truth is not None:
                self._truth.drain()
        elif chunk.kind == "event" and outcome == "damaged" and chunk.damaged_by is not None:
            entries[chunk.damaged_by].corrupted_events += 1

    def _write_log(self, now: int) -> None:
        self._log_written_ns = now
        if self._fault_log_path is not None:
            self.fault_log.write(self._fault_log_path)
