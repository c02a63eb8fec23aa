"""Session time of every frame of a recording, from the timer's edges of the frame pulses.

A timer stream (docs/protocols/timer.md) stamps, on its 10 MHz counter, the frame pulse
of every device wired to one of its inputs. :func:`session_timebase` pairs each device
frame with the edge of its own pulse, fits the device's :class:`ClockModel` (device
ticks to timer seconds: steps, resets and wraps as events) and gives every frame its
session time: ``(timer counter - counter of the timer's first frame) / 1e7`` s, the
timer being the reference. Devices without a timer input, and recordings without a
timer, fall back to host arrival stamps (:func:`dejitter_arrivals`), and the report says
so. See docs/synchronisation.md, section "From a recording".

Pairing a frame with its edge. A device counts frames it takes (``seq``, plus the frame
periods its ticks skip when it drops frames itself); the timer counts the edges of an
input (``edge_index``, lost edges included). Both counters advance by one per frame
pulse, so within a run (device and timer streaming without restart) ``pulse =
frame_index + k`` for one integer ``k``. The periodic pulses alone do not tell ``k``:
it comes from the host arrival stamps, as the most common offset between each frame
and the edge nearest to it in host time (lower envelope of the arrivals, with the
frame's acquisition span of time-multiplexed slots removed, and the delay its stream
declares before a frame can leave, ``frame_delay_s``: :func:`delivery_delay_s`). This
needs the two
streams' fastest deliveries to differ by less than half a frame period (about 1 ms
here against 5-10 ms periods). A clock step or reset does not move ``k``: the pairs
carry it to :func:`fit_edges`, which finds it.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from spotlab.acquisition._frame_pulses import (
    ChannelEdges,
    PulsedDevice,
    assign_channels,
    channel_edges,
    delivery_delay_s,
    frame_edge_pairs,
    host_times,
    pulsed_device,
)
from spotlab.acquisition.clocks import ClockModel, dejitter_arrivals, fit_edges
from spotlab.acquisition.recorded_frames import DeviceFrames, TimerFrames
from spotlab.acquisition.synchroniser import sample_times
from spotlab.core.errors import ClockError, SynchronisationError
from spotlab.core.streams import StreamSpec

I64 = npt.NDArray[np.int64]
F64 = npt.NDArray[np.float64]
B = npt.NDArray[np.bool_]

#: Session seconds per timer tick (the TMR counter runs at 10 MHz).
TIMER_TICK_HZ = 1e7
#: Per-frame ``method`` codes of :class:`StreamTiming`.
METHODS = ("reference", "edge", "model", "extrapolated", "arrivals")


@dataclass
class StreamTiming:
    """Session times of one stream's frames and how they were found.

    Attributes
    ----------
    name : str
        Stream name.
    seq, ticks : ndarray of int64, shape (F,)
        As recorded.
    time_s : ndarray of float64, shape (F,)
        Session time of each frame's first sample, s.
    method : ndarray of str, shape (F,)
        Per frame: ``reference`` (the timer's own frames), ``edge`` (the time of the
        frame's own edge), ``model`` (between fitted edges: its edge was lost),
        ``extrapolated`` (outside the span of its clock segment's edges), ``arrivals``.
    model : ClockModel or None
        Device ticks to session seconds (None for the timer).
    channel : int or None
        Timer input of the stream's frame pulses.
    notes : list of str
        What went wrong or was assumed, one line each.
    spec : StreamSpec or None
        The stream's spec (for sample times).
    """

    name: str
    seq: I64
    ticks: I64
    time_s: F64
    method: npt.NDArray[np.str_]
    model: ClockModel | None = None
    channel: int | None = None
    notes: list[str] = field(default_factory=list)
    spec: StreamSpec | None = None
    pairs: int = 0

    def sample_times(self) -> F64:
        """Session time of every sample, (F, M) with slot offsets, or (F,) without slots.

        Raises
        ------
        SynchronisationError
            If the stream has no spec.
        """
        if self.spec is None:
            raise SynchronisationError(f"stream {self.name!r}: no spec, no sample offsets")
        return sample_times(self.time_s, self.spec, clock_rate=self.clock_rate)

    @property
    def clock_rate(self) -> float:
        """Session seconds per device second (``1 + drift``; the median over the clock
        model's segments), 1.0 without a model or spec."""
        if self.model is None or self.spec is None:
            return 1.0
        return float(np.median([s.rate for s in self.model.segments])) * self.spec.tick_hz

    def report(self) -> dict[str, Any]:
        """JSON-safe summary: method, pairs, drift, jitter, events, notes."""
        counts = {m: int(np.sum(self.method == m)) for m in METHODS if np.any(self.method == m)}
        out: dict[str, Any] = {
            "stream": self.name,
            "frames": int(self.seq.shape[0]),
            "methods": counts,
            "channel": self.channel,
            "pairs": self.pairs,
            "notes": list(self.notes),
        }
        if self.model is not None:
            m = self.model
            out.update(
                method=m.method,
                drift_ppm=m.drift_ppm,
                jitter_us=m.jitter_s * 1e6,
                residual_max_us=float(np.max(np.abs(m.residuals)) * 1e6)
                if m.residuals.size
                else 0.0,
                segments=len(m.segments),
                events=[
                    {"kind": e.kind, "at_tick": e.at_tick, "size_s": e.size_s} for e in m.events
                ],
            )
        else:
            out.update(method="reference" if self.channel is None else "", events=[])
        return out


@dataclass
class SessionTimebase:
    """Session times of every stream of a recording.

    Attributes
    ----------
    reference : str
        Name of the timer stream, or ``"host"`` when times come from arrival stamps.
    origin_tick : int
        Timer counter (or host ns) at session time 0.
    streams : dict of str to StreamTiming
        Per stream, in recording order.
    notes : list of str
        Session-wide warnings (no timer, the timer stopped, a stream not found, ...).
    """

    reference: str
    origin_tick: int
    streams: dict[str, StreamTiming]
    notes: list[str] = field(default_factory=list)

    def report(self) -> dict[str, Any]:
        """The clock report: reference, notes, and per stream drift, jitter and events."""
        return {
            "reference": self.reference,
            "origin_tick": self.origin_tick,
            "notes": list(self.notes),
            "streams": [s.report() for s in self.streams.values()],
        }


# -- arrival stamps -------------------------------------------------------------------


def _arrival_times(
    frames: DeviceFrames, to_session: Callable[[F64], F64], reason: str
) -> StreamTiming:
    """Fallback: dejittered arrival stamps (their lower envelope), mapped to session time."""
    spec = frames.spec
    notes = [reason]
    method = np.full(frames.seq.shape, "arrivals")
    if frames.seq.shape[0] < 3:
        notes.append("fewer than 3 frames: no times")
        return StreamTiming(
            frames.name, frames.seq, frames.ticks, np.full(frames.seq.shape, np.nan), method,
            notes=notes, spec=spec,
        )  # fmt: skip
    # the lower envelope first: frames queued before the reader started (or behind a busy
    # host) arrive late in bursts, which would bend the recursive line fit
    host = host_times(frames.ticks, frames.arrival_ns, spec.tick_hz, spec.rate_hz)
    host -= delivery_delay_s(spec)
    res = dejitter_arrivals(frames.ticks, host, spec.tick_hz, allow_resets=True)
    times = to_session(res.model(frames.ticks))
    if not _increasing_within_epochs(frames.ticks, times):
        # A step found in the arrivals alone can be a burst of late deliveries (a busy
        # host, a device whose frames waited in its port): the segments' lines then
        # disagree and frame times would run backwards. One line per epoch instead.
        res = dejitter_arrivals(frames.ticks, host, spec.tick_hz, k=math.inf, allow_resets=True)
        times = to_session(res.model(frames.ticks))
        notes.append(
            "the clock steps seen in the arrival stamps made frame times run backwards: "
            "one line per clock epoch instead"
        )
    return StreamTiming(
        frames.name, frames.seq, frames.ticks, np.asarray(times, dtype=np.float64), method,
        model=res.model, notes=notes, spec=spec,
    )  # fmt: skip


def _increasing_within_epochs(ticks: npt.NDArray[np.int64], times: F64) -> bool:
    """Whether ``times`` increase wherever ``ticks`` do (a tick reset starts a new epoch)."""
    forward = np.diff(ticks) > 0
    return bool(np.all(np.diff(times)[forward] > 0))


def _edge_times(dev: PulsedDevice, edges: ChannelEdges, channel: int, origin: int) -> StreamTiming:
    frames = dev.frames
    fi, ej = frame_edge_pairs(dev, edges)
    if fi.shape[0] < 3:
        raise ClockError(f"only {fi.shape[0]} frames paired with edges of timer input {channel}")
    fi_order = np.argsort(fi, kind="stable")
    fi, ej = fi[fi_order], ej[fi_order]
    ref = (edges.tick[ej] - origin).astype(np.float64) / TIMER_TICK_HZ
    model = fit_edges(frames.ticks[fi], ref, frames.spec.tick_hz, allow_resets=True)
    times = model(frames.ticks)
    # a frame with its own edge takes the edge's time: the pulse is the frame's instant,
    # the device tick may carry trigger jitter and is rounded to the device's tick
    times[fi] = ref
    method = np.full(frames.seq.shape, "model", dtype="<U12")
    method[fi] = "edge"
    epochs = model.epochs_of(frames.ticks)
    pair_epochs = epochs[fi]
    for e in np.unique(epochs):
        rows = np.flatnonzero(epochs == e)
        inside = pair_epochs == e
        if not np.any(inside):
            method[rows] = "extrapolated"
            continue
        lo, hi = frames.ticks[fi[inside]].min(), frames.ticks[fi[inside]].max()
        out = (frames.ticks[rows] < lo) | (frames.ticks[rows] > hi)
        method[rows[out]] = "extrapolated"
    timing = StreamTiming(
        frames.name, frames.seq, frames.ticks, times, method, model=model, channel=channel,
        spec=frames.spec, pairs=int(fi.shape[0]),
    )  # fmt: skip
    n_ex = int(np.sum(method == "extrapolated"))
    if n_ex:
        timing.notes.append(
            f"{n_ex} frames outside the span of their timer edges: times extrapolated by the "
            "clock model"
        )
    for ev in model.events:
        timing.notes.append(
            f"clock {ev.kind} of {ev.size_s * 1e3:+.3f} ms at device tick {ev.at_tick}"
        )
    return timing


def session_timebase(
    devices: Sequence[DeviceFrames],
    timer: TimerFrames | None,
    wiring: Mapping[str, int] | None = None,
) -> SessionTimebase:
    """Session time of every frame of every stream of a recording.

    Parameters
    ----------
    devices : sequence of DeviceFrames
        Every device stream except the timer.
    timer : TimerFrames or None
        The timer stream; None: times from host arrival stamps only.
    wiring : mapping of str to int, optional
        Timer input of each stream's frame pulses; streams not named are matched to
        the input whose edges follow their frames (in host time) best.

    Returns
    -------
    SessionTimebase
        A stream that cannot be timed from edges (no input, too few pairs, a bad clock)
        falls back to arrival stamps with a note; it never changes another stream.

    Raises
    ------
    SynchronisationError
        If a timer is given without frames, or its counter goes backwards.
    """
    notes: list[str] = []
    streams: dict[str, StreamTiming] = {}
    if timer is None:
        firsts = [int(d.arrival_ns[0]) for d in devices if d.arrival_ns.shape[0]]
        origin = min(firsts) if firsts else 0
        notes.append(
            "no timer stream in the recording: session times come from host arrival stamps "
            "(dejittered), millisecond-level, each stream biased by its transmission delay"
        )
        if wiring:
            notes.append(f"timer wiring of {', '.join(sorted(wiring))} ignored: no timer")

        def host_seconds(host_s: F64) -> F64:
            return np.asarray(host_s - origin * 1e-9, dtype=np.float64)

        for d in devices:
            streams[d.name] = _arrival_times(d, host_seconds, "no timer: arrival stamps")
        return SessionTimebase("host", origin, streams, notes)

    if timer.ticks.shape[0] < 3:
        raise SynchronisationError(f"timer stream {timer.name!r} holds fewer than 3 frames")
    if np.any(np.diff(timer.ticks) <= 0):
        bad = int(np.flatnonzero(np.diff(timer.ticks) <= 0)[0]) + 1
        raise SynchronisationError(
            f"timer stream {timer.name!r}: counter does not increase at frame seq "
            f"{int(timer.seq[bad])}; the timer was reset"
        )
    origin = int(timer.ticks[0])
    t_rate = TIMER_TICK_HZ / float(np.median(np.diff(timer.ticks)))
    timer_host = host_times(timer.ticks, timer.arrival_ns, TIMER_TICK_HZ, t_rate)
    streams[timer.name] = StreamTiming(
        timer.name, timer.seq, timer.ticks,
        (timer.ticks - origin).astype(np.float64) / TIMER_TICK_HZ,
        np.full(timer.seq.shape, "reference", dtype="<U12"),
    )  # fmt: skip

    # host seconds -> session seconds through the timer's frames (earliest delivery)
    def host_to_session(host_s: F64) -> F64:
        x = (timer.ticks - origin).astype(np.float64) / TIMER_TICK_HZ
        a, b = np.polyfit(timer_host - timer_host[0], x, 1)
        return np.asarray(a * (host_s - timer_host[0]) + b, dtype=np.float64)

    last_timer = float(timer.arrival_ns[-1]) * 1e-9
    channels: dict[int, ChannelEdges] = {}
    for ch in np.unique(timer.edge_input):
        got = channel_edges(timer, int(ch), timer_host)
        if got is not None and ch < 128:
            channels[int(ch)] = got
    prepared: dict[str, PulsedDevice] = {}
    for d in devices:
        if d.seq.shape[0] < 3:
            streams[d.name] = _arrival_times(d, host_to_session, "fewer than 3 frames")
            continue
        prepared[d.name] = pulsed_device(d)
        late = d.arrival_ns[-1] * 1e-9 - last_timer
        if late > 1.0:
            notes.append(
                f"the timer stopped {late:.1f} s before the last frame of {d.name!r}: its later "
                "frames are extrapolated by its clock model"
            )
    assigned = assign_channels(prepared, channels, wiring or {}, notes)
    for name, dev in prepared.items():
        ch = assigned.get(name)
        if ch is None:
            streams[name] = _arrival_times(
                dev.frames, host_to_session,
                "no timer input follows this stream's frame pulses: times from arrival stamps "
                "(millisecond-level, biased by the transmission delay)",
            )  # fmt: skip
            continue
        try:
            streams[name] = _edge_times(dev, channels[ch], ch, origin)
        except (ClockError, SynchronisationError) as exc:
            streams[name] = _arrival_times(
                dev.frames, host_to_session, f"timer input {ch}: {exc}; times from arrival stamps"
            )
    order = [timer.name, *[d.name for d in devices]]
    return SessionTimebase(timer.name, origin, {n: streams[n] for n in order}, notes)
