"""Clock models from timer edges: device frame ticks paired with reference edge times.

A timer (sync device) timestamps the frame pulse of each device on its own clock, the
session reference; the device stamps the same frame with its own ticks. Offline,
:func:`fit_edges` fits the whole record (robust line per segment, steps found by a
changepoint test); live, :class:`EdgeClockEstimator` takes the pairs one block at a
time and keeps a current model.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from spotlab.acquisition.clocks.model import ClockEvent, ClockModel, ClockSegment
from spotlab.acquisition.clocks.pairs import MIN_PAIRS, as_pairs, event_kind, fit_pairs
from spotlab.core.errors import ClockError


def fit_edges(
    ticks: npt.ArrayLike,
    ref_s: npt.ArrayLike,
    tick_hz: float,
    *,
    allow_resets: bool = False,
    k: float = 8.0,
    window: int = 16,
    min_step_s: float = 0.0,
) -> ClockModel:
    """Clock model of one device from timer edges of its frames.

    Parameters
    ----------
    ticks : array_like of int, shape (N,)
        Device ticks of the frames (unwrapped int64), in acquisition order.
    ref_s : array_like of float, shape (N,)
        Session (timer) time of the same frames' edges, s; must increase.
    tick_hz : float
        Nominal device tick rate, Hz.
    allow_resets : bool
        Fit a new epoch where ticks go backwards (else ClockError).
    k, window, min_step_s
        Step detection: threshold ``max(k * jitter, min_step_s)`` on the jump of the
        windowed medians of the residuals (``window`` pairs on each side).

    Returns
    -------
    ClockModel
        ``method="edges"``; steps, wraps and resets as events.

    Raises
    ------
    ClockError
        Fewer than 3 pairs, NaN, repeated ticks, ticks going backwards (unless allowed),
        a reference that stops or goes backwards.
    """
    return fit_pairs(
        ticks,
        ref_s,
        tick_hz,
        allow_resets=allow_resets,
        k=k,
        window=window,
        min_step_s=min_step_s,
        method="edges",
    )


class _Segment:
    """Running least-squares line of one segment (Welford co-moments)."""

    def __init__(self, epoch: int, tick: int, ref: float) -> None:
        self.epoch = epoch
        self.origin = tick
        self.y0 = ref
        self.first = tick
        self.last = tick
        self.n = 0
        self.mx = self.my = self.sxx = self.sxy = self.syy = 0.0

    def add(self, tick: int, ref: float) -> None:
        x = float(tick - self.origin)
        y = ref - self.y0
        self.n += 1
        dx = x - self.mx
        self.mx += dx / self.n
        dy = y - self.my
        self.my += dy / self.n
        self.sxx += dx * (x - self.mx)
        self.sxy += dx * (y - self.my)
        self.syy += dy * (y - self.my)
        self.last = tick

    @property
    def rate(self) -> float:
        return self.sxy / self.sxx

    def predict(self, tick: int) -> float:
        return self.y0 + self.my + self.rate * (float(tick - self.origin) - self.mx)

    @property
    def jitter(self) -> float:
        if self.n < 3:
            return 0.0
        sse = max(self.syy - self.sxy**2 / self.sxx, 0.0)
        return math.sqrt(sse / (self.n - 2))

    def segment(self) -> ClockSegment:
        j = self.jitter
        return ClockSegment(
            epoch=self.epoch,
            tick_start=self.first,
            tick_end=self.last,
            origin=self.origin,
            offset_s=self.y0 + self.my - self.rate * self.mx,
            rate=self.rate,
            n=self.n,
            jitter_s=j,
            rms_s=j,
            max_abs_s=0.0,
        )


class EdgeClockEstimator:
    """Online clock model from timer edges, one block of pairs at a time (live path).

    A pair whose residual against the current segment exceeds ``max(k * jitter,
    min_step_s)`` is held back; ``confirm`` such pairs in a row that agree with each
    other start a new segment (a step, or a wrap when the jump is a whole number of
    counter periods) at the first of them, while a lone outlier is dropped. Ticks
    going backwards start a new epoch (``allow_resets``) or raise ClockError.

    Parameters
    ----------
    tick_hz : float
        Nominal device tick rate, Hz.
    k : float
        Threshold in jitters.
    confirm : int
        Consecutive deviating pairs that make a step.
    warmup : int
        Pairs accepted without a test at the start of each segment.
    min_step_s : float
        Smallest step, s (also the threshold floor).
    allow_resets : bool
        Ticks going backwards start a new epoch instead of raising.

    Examples
    --------
    >>> import numpy as np
    >>> est = EdgeClockEstimator(1e6)
    >>> ticks = np.arange(20, dtype=np.int64) * 10_000 + 7
    >>> est.update(ticks, ticks * 1e-6 + 1.0)
    >>> round(float(est.model(np.array([7]))[0]), 9)
    1.000007
    """

    def __init__(
        self,
        tick_hz: float,
        *,
        k: float = 8.0,
        confirm: int = 3,
        warmup: int = 8,
        min_step_s: float = 0.0,
        allow_resets: bool = False,
    ) -> None:
        if not (math.isfinite(tick_hz) and tick_hz > 0):
            raise ClockError(f"tick rate must be finite and positive, got {tick_hz}")
        if confirm < 1 or warmup < MIN_PAIRS:
            raise ClockError(f"confirm must be >= 1 and warmup >= {MIN_PAIRS}")
        self.tick_hz = float(tick_hz)
        self.k = float(k)
        self.confirm = int(confirm)
        self.warmup = int(warmup)
        self.min_step_s = float(min_step_s)
        self.allow_resets = allow_resets
        self._floor = 1.0 / self.tick_hz / math.sqrt(12.0)
        self._closed: list[_Segment] = []
        self._current: _Segment | None = None
        self._pending: list[tuple[int, float, float]] = []
        self._last: tuple[int, float] | None = None
        self._events: list[ClockEvent] = []
        self._count = 0
        self.outliers = 0

    @property
    def events(self) -> tuple[ClockEvent, ...]:
        """Steps, wraps and resets seen so far."""
        return tuple(self._events)

    def update(self, ticks: npt.ArrayLike, ref_s: npt.ArrayLike) -> None:
        """Take the next block of pairs, shapes (N,) each (N may be 0).

        Raises
        ------
        ClockError
            NaN, repeated ticks, ticks going backwards (unless ``allow_resets``), a
            reference that does not advance.
        """
        tk = np.asarray(ticks)
        ref = np.asarray(ref_s, dtype=np.float64)
        if tk.size == 0 and ref.size == 0:
            return
        if tk.size < MIN_PAIRS:
            # as_pairs wants >= 3 pairs; validate small blocks by padding with themselves
            tk_v, ref_v = as_pairs(np.resize(tk, MIN_PAIRS), np.resize(ref, MIN_PAIRS))
            tk_v, ref_v = tk_v[: tk.size], ref_v[: tk.size]
        else:
            tk_v, ref_v = as_pairs(tk, ref)
        for x, y in zip(tk_v.tolist(), ref_v.tolist(), strict=True):
            self._add(int(x), float(y))

    def _add(self, x: int, y: float) -> None:
        index = self._count
        self._count += 1
        if self._last is not None:
            lx, ly = self._last
            if y <= ly:
                raise ClockError(
                    f"reference time does not advance at pair {index} ({ly!r} -> {y!r} s): "
                    "the reference stopped, repeated or went backwards"
                )
            if x == lx:
                raise ClockError(f"ticks repeat at pair {index} ({x})")
            if x < lx:
                if not self.allow_resets:
                    raise ClockError(
                        f"ticks go backwards at pair {index} ({lx} -> {x}): the device clock "
                        "was reset or stepped back; use allow_resets=True to start a new epoch"
                    )
                self._start_new(x, y, index, kind="reset")
                self._last = (x, y)
                return
        self._last = (x, y)
        cur = self._current
        if cur is None:
            self._current = _Segment(0, x, y)
            self._current.add(x, y)
            return
        if cur.n < self.warmup:
            cur.add(x, y)
            return
        r = y - cur.predict(x)
        threshold = max(self.k * max(cur.jitter, self._floor), self.min_step_s)
        if abs(r) <= threshold:
            cur.add(x, y)
            self.outliers += len(self._pending)
            self._pending.clear()
            return
        self._pending.append((x, y, r))
        if len(self._pending) < self.confirm:
            return
        rs = np.array([p[2] for p in self._pending])
        if np.all(np.sign(rs) == np.sign(rs[0])) and np.ptp(rs) <= threshold:
            first = self._pending[0]
            rest = self._pending[1:]
            self._pending = []
            self._start_new(first[0], first[1], index - len(rest), kind="step")
            for px, py, _ in rest:
                assert self._current is not None
                self._current.add(px, py)
        else:
            self.outliers += 1
            self._pending.pop(0)

    def _start_new(self, x: int, y: float, index: int, kind: str) -> None:
        cur = self._current
        assert cur is not None
        epoch = cur.epoch + (1 if kind == "reset" else 0)
        rate = cur.rate if cur.n >= 2 else 1.0 / self.tick_hz
        # device jump: ticks seen minus ticks the old segment expects at this reference time
        expected_x = cur.origin + (y - cur.y0 - cur.my) / rate + cur.mx
        size_s = (x - expected_x) / self.tick_hz
        if kind == "step":
            gap = (y - (self._pending_ref_before(cur))) / rate
            kind = event_kind(x - cur.last, gap, max(20.0 * cur.jitter / rate, 4.0))
        self.outliers += len(self._pending)
        self._pending = []
        if cur.n >= 2:
            self._closed.append(cur)
        self._events.append(ClockEvent(kind=kind, at_tick=x, size_s=size_s, index=index))
        self._current = _Segment(epoch, x, y)
        self._current.add(x, y)

    @staticmethod
    def _pending_ref_before(cur: _Segment) -> float:
        return cur.predict(cur.last)

    @property
    def model(self) -> ClockModel:
        """The current clock model (closed segments and the running one).

        Raises
        ------
        ClockError
            Fewer than 3 pairs accepted so far.
        """
        segs = [s for s in [*self._closed, self._current] if s is not None and s.n >= MIN_PAIRS]
        if not segs:
            raise ClockError(f"too few pairs for a clock model yet (need {MIN_PAIRS})")
        return ClockModel(
            self.tick_hz, [s.segment() for s in segs], self._events, method="edges-online"
        )
