"""What every MCS-1 stream shares: the frame schedule, the taken frame, the encoding.

A stream is the device's frames of one ``START:`` .. ``STOP:`` period. Frame
``k`` starts at oscillator time ``start + k / rate``
(:func:`~spotlab.simulators.lab.frame_start`: its tick is the counter rounded
to whole µs); a family says when the frame is complete and queued for
sending (:meth:`Mcs1Stream._ready_osc`), and what it holds
(:meth:`Mcs1Stream.take`: the payload with a zero status word, and the truth
row). :class:`~spotlab.simulators.mcs1_device.Mcs1Device` decides whether a
taken frame is sent and then asks :meth:`Mcs1Stream.encode` for its bytes,
with the status word and header flags in force at that moment.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass

from spotlab.simulators import wire
from spotlab.simulators.clock import DeviceClock
from spotlab.simulators.lab import frame_start
from spotlab.simulators.truth import TruthRow

#: Byte offset of the status word in every MCS-1 payload (after frame_no and tick).
STATUS_OFFSET = 8


@dataclass
class TakenFrame:
    """A frame the device has taken, before it decides whether to send it.

    Attributes
    ----------
    frame_no : int
        Frame periods since ``START:``.
    device_us : int
        Tick of the frame (device µs, unwrapped).
    payload : bytes
        The frame's payload with a zero status word (:data:`STATUS_OFFSET`).
    ambient_high : bool
        Set the status word's ambient-light bit in this frame.
    resynced : bool
        The device clock stepped since the previous frame.
    truth : TruthRow
        The frame's ground-truth row.
    """

    frame_no: int
    device_us: int
    payload: bytes
    ambient_high: bool
    resynced: bool
    truth: TruthRow

    @property
    def frame_bytes(self) -> int:
        """Bytes of the whole data frame: the payload and the MCS-1 framing."""
        return len(self.payload) + wire.FRAME_OVERHEAD


class Mcs1Stream(ABC):
    """Frames of one ``START:`` .. ``STOP:`` period of an MCS-1 device.

    A subclass sets what :meth:`_ready_osc` reads, then calls this constructor,
    and supplies :meth:`take` (ending in :meth:`_finish`) and :meth:`_frame`.

    Parameters
    ----------
    clock : DeviceClock
        The device's clock.
    index : int
        Stream number since power-up (0 first).
    rate_mhz : int
        Frame rate in mHz.
    start_ns : int
        World time the stream starts (``START:`` received).
    """

    def __init__(self, clock: DeviceClock, index: int, rate_mhz: int, start_ns: int) -> None:
        self.clock = clock
        self.index = index
        self.period_s = 1000.0 / rate_mhz
        self.start_ns = start_ns
        self.start_osc = clock.osc_s(start_ns)
        self.frame_no = 0
        self.seq = 0
        self._steps_seen = clock.step_count(self.start_osc)
        self.ready_ns, self._tick, self._osc0 = self._timing(0)

    def _timing(self, k: int) -> tuple[int, int, float]:
        """(ready world ns, tick in µs unwrapped, true oscillator start) of frame ``k``."""
        tick, osc0 = frame_start(self.clock, self.start_osc, self.period_s, k)
        return self.clock.world_ns_at(self._ready_osc(osc0)), tick, osc0

    @abstractmethod
    def _ready_osc(self, osc0: float) -> float:
        """Oscillator time (s) the frame starting at ``osc0`` is complete and queued."""

    @abstractmethod
    def take(self) -> TakenFrame:
        """Take the frame that is ready now (and schedule the next one: :meth:`_finish`)."""

    @abstractmethod
    def _frame(self, seq: int, payload: bytes, flags: int) -> bytes:
        """The whole data frame of ``payload`` (the family's frame type)."""

    def _finish(self, payload: bytes, truth: TruthRow, ambient_high: bool = False) -> TakenFrame:
        """The frame now being taken, with the clock steps seen; then schedule the next."""
        steps = self.clock.step_count(self._osc0)
        taken = TakenFrame(
            frame_no=self.frame_no,
            device_us=self._tick,
            payload=payload,
            ambient_high=ambient_high,
            resynced=steps != self._steps_seen,
            truth=truth,
        )
        self._steps_seen = steps
        self.frame_no += 1
        self.ready_ns, self._tick, self._osc0 = self._timing(self.frame_no)
        return taken

    def encode(self, taken: TakenFrame, status: int, flags: int) -> bytes:
        """The whole data frame of ``taken`` with this stream's next seq (then seq += 1)."""
        payload = bytearray(taken.payload)
        payload[STATUS_OFFSET : STATUS_OFFSET + 2] = (status & 0xFFFF).to_bytes(2, "little")
        data = self._frame(self.seq, bytes(payload), flags)
        self.seq = (self.seq + 1) & 0xFFFF
        return data
