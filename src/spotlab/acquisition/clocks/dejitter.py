r"""Clock models from host arrival stamps: a recursive line fit with forgetting.

Each frame arrives at the host some queueing delay after it was taken. liblsl's
dejitter post-processing (time_postprocessor.cpp, pylsl flag ``proc_dejitter``; see
shared/research/protocols.md section 1.4) fits the time stamps against the sample
index by recursive least squares with forgetting factor
:math:`\lambda = 2^{-1/(f_s \cdot 90\,\mathrm{s})}`, a half-life of 90 s. Here the
line is fitted against the device ticks instead of the sample index (so dropped frames
do not bend it), with the forgetting factor per pair
:math:`\lambda_i = 2^{-\Delta t_i / T_{1/2}}`, :math:`\Delta t_i` the device time since
the previous pair: the same 90 s half-life at any frame rate.

The RLS recursion for :math:`\theta = (a, b)`, regressor :math:`\varphi = (1, x)`:

.. math:: g = \frac{P\varphi}{\lambda + \varphi^T P \varphi}, \quad
          \theta \leftarrow \theta + g\,(y - \varphi^T\theta), \quad
          P \leftarrow (P - g\varphi^T P)/\lambda.

The fitted line passes through the *mean* delay, not the transmission instant: every
frame's time carries the mean queueing delay of its device, a bias between devices
that no arrival fit can see (measured in benchmarks/clock_alignment.py). A step of
the device clock shows as ``confirm`` residuals in a row beyond ``k`` jitters; the
fit restarts there.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from spotlab.acquisition.clocks.linefit import robust_sd
from spotlab.acquisition.clocks.model import ClockEvent, ClockModel, ClockSegment
from spotlab.acquisition.clocks.pairs import MIN_PAIRS, as_pairs
from spotlab.core.errors import ClockError

I64 = npt.NDArray[np.int64]
F64 = npt.NDArray[np.float64]


@dataclass(frozen=True)
class DejitterResult:
    """Per-frame smoothed times and the clock model of an arrival fit.

    Attributes
    ----------
    times_s : ndarray of float64, shape (N,)
        Smoothed time of each frame, s (the recursive fit after that frame).
    model : ClockModel
        Final line of each segment; ``residuals`` = arrival minus smoothed time.
    """

    times_s: F64
    model: ClockModel


class ArrivalDejitter:
    """Online recursive line fit of host arrival times against device ticks.

    Parameters
    ----------
    tick_hz : float
        Nominal device tick rate, Hz.
    half_life_s : float
        Half-life of the forgetting, s of device time (liblsl: 90 s).
    k : float
        Step threshold in jitters (running RMS of the residuals).
    confirm : int
        Consecutive residuals beyond the threshold, all of one sign, that make a step.
    allow_resets : bool
        Ticks going backwards start a new epoch instead of raising ClockError.
    """

    def __init__(
        self,
        tick_hz: float,
        *,
        half_life_s: float = 90.0,
        k: float = 8.0,
        confirm: int = 5,
        allow_resets: bool = False,
    ) -> None:
        if not (math.isfinite(tick_hz) and tick_hz > 0):
            raise ClockError(f"tick rate must be finite and positive, got {tick_hz}")
        if not half_life_s > 0:
            raise ClockError(f"half-life must be > 0 s, got {half_life_s}")
        self.tick_hz = float(tick_hz)
        self.half_life_s = float(half_life_s)
        self.k = float(k)
        self.confirm = int(confirm)
        self.allow_resets = allow_resets
        self._segments: list[ClockSegment] = []
        self._events: list[ClockEvent] = []
        self._epoch = 0
        self._origin: int | None = None
        self._y0 = 0.0
        self._first = 0
        self._theta = np.zeros(2)
        self._p = np.eye(2)
        self._n = 0
        self._ms = 0.0  # running mean square residual
        self._last: int | None = None
        self._seg_last = 0
        self._pending: list[tuple[int, float, float]] = []
        self._count = 0

    def _restart(self, x: int, y: float) -> None:
        self._origin, self._y0, self._first = x, y, x
        # a: seconds at origin; b: session seconds per device second
        self._theta = np.array([0.0, 1.0])
        self._p = np.diag([1.0, 1e-2])
        self._n = 0

    def _close(self) -> None:
        if self._origin is None or self._n < MIN_PAIRS:
            return
        b = float(self._theta[1])
        self._segments.append(
            ClockSegment(
                epoch=self._epoch,
                tick_start=self._first,
                tick_end=self._seg_last,
                origin=self._origin,
                offset_s=self._y0 + float(self._theta[0]),
                rate=b / self.tick_hz,
                n=self._n,
                jitter_s=math.sqrt(self._ms),
                rms_s=math.sqrt(self._ms),
            )
        )

    def update(self, ticks: npt.ArrayLike, arrival_s: npt.ArrayLike) -> F64:
        """Take a block of frames, shapes (N,); return their smoothed times, s, shape (N,)."""
        tk = np.asarray(ticks)
        if tk.size == 0:
            return np.zeros(0)
        tk_v, ref_v = as_pairs(
            np.resize(tk, max(tk.size, MIN_PAIRS)),
            np.resize(np.asarray(arrival_s, dtype=np.float64), max(tk.size, MIN_PAIRS)),
            "arrival",
        )
        out = np.empty(tk.size)
        for i, (x, y) in enumerate(
            zip(tk_v[: tk.size].tolist(), ref_v[: tk.size].tolist(), strict=True)
        ):
            out[i] = self._add(int(x), float(y))
        return out

    def _add(self, x: int, y: float) -> float:
        index = self._count
        self._count += 1
        if self._last is not None and x <= self._last:
            if x == self._last:
                raise ClockError(f"ticks repeat at frame {index} ({x})")
            if not self.allow_resets:
                raise ClockError(
                    f"ticks go backwards at frame {index} ({self._last} -> {x}); use "
                    "allow_resets=True to start a new epoch"
                )
            self._close()
            size = (x - self._predict_ticks(y)) / self.tick_hz
            self._events.append(ClockEvent("reset", x, size, index))
            self._epoch += 1
            self._origin = None
            self._pending = []
        if self._origin is None:
            self._restart(x, y)
            return self._step(x, y)
        e = y - self._predict(x)
        if self._n >= 8 and abs(e) > self.k * math.sqrt(self._ms):
            if self._pending and np.sign(self._pending[0][2]) != np.sign(e):
                self._pending = []
            self._pending.append((x, y, e))
            self._last = x
            if len(self._pending) < self.confirm:
                return self._predict(x)
            # a step: restart the fit at the first deviating frame and replay the run
            run, self._pending = self._pending, []
            self._close()
            size = -float(np.median([p[2] for p in run]))
            self._events.append(ClockEvent("step", run[0][0], size, index - len(run) + 1))
            self._restart(run[0][0], run[0][1])
            for px, py, _ in run[:-1]:
                self._step(px, py)
            return self._step(x, y)
        self._pending = []
        return self._step(x, y)

    def _predict(self, x: int) -> float:
        assert self._origin is not None
        dx_s = (x - self._origin) / self.tick_hz
        return self._y0 + float(self._theta[0] + self._theta[1] * dx_s)

    def _step(self, x: int, y: float) -> float:
        """One RLS update with the pair (x, y); returns the smoothed time of x."""
        assert self._origin is not None
        phi = np.array([1.0, (x - self._origin) / self.tick_hz])
        e = y - self._y0 - float(phi @ self._theta)
        if self._n > 0 and self._last is not None:
            lam = 2.0 ** (-((x - self._last) / self.tick_hz) / self.half_life_s)
        else:
            lam = 1.0
        p_phi = self._p @ phi
        gain = p_phi / (lam + float(phi @ p_phi))
        self._theta = self._theta + gain * e
        self._p = (self._p - np.outer(gain, p_phi)) / lam
        self._n += 1
        smoothed = self._y0 + float(phi @ self._theta)
        resid = y - smoothed
        w = 1.0 / min(self._n, 200)
        self._ms = (1.0 - w) * self._ms + w * resid * resid
        self._last = x
        self._seg_last = x
        return smoothed

    def _predict_ticks(self, y: float) -> float:
        assert self._origin is not None
        a, b = float(self._theta[0]), float(self._theta[1])
        return self._origin + (y - self._y0 - a) / b * self.tick_hz

    @property
    def events(self) -> tuple[ClockEvent, ...]:
        """Steps and resets seen so far."""
        return tuple(self._events)

    @property
    def model(self) -> ClockModel:
        """Clock model from the closed segments and the current fit."""
        segs = list(self._segments)
        if self._origin is not None and self._n >= MIN_PAIRS and self._last is not None:
            b = float(self._theta[1])
            segs.append(
                ClockSegment(
                    epoch=self._epoch,
                    tick_start=self._first,
                    tick_end=self._seg_last,
                    origin=self._origin,
                    offset_s=self._y0 + float(self._theta[0]),
                    rate=b / self.tick_hz,
                    n=self._n,
                    jitter_s=math.sqrt(self._ms),
                    rms_s=math.sqrt(self._ms),
                )
            )
        if not segs:
            raise ClockError(f"too few frames for a clock model yet (need {MIN_PAIRS})")
        return ClockModel(self.tick_hz, segs, self._events, method="arrivals")


def dejitter_arrivals(
    ticks: npt.ArrayLike,
    arrival_s: npt.ArrayLike,
    tick_hz: float,
    *,
    half_life_s: float = 90.0,
    k: float = 8.0,
    allow_resets: bool = False,
) -> DejitterResult:
    """Smoothed frame times from host arrival stamps (offline form of :class:`ArrivalDejitter`).

    Parameters
    ----------
    ticks : array_like of int, shape (N,)
        Device ticks of the frames, in arrival order.
    arrival_s : array_like of float, shape (N,)
        Host arrival time of each frame, s.
    tick_hz, half_life_s, k, allow_resets
        As in :class:`ArrivalDejitter`.

    Returns
    -------
    DejitterResult

    Raises
    ------
    ClockError
        Fewer than 3 frames, NaN, repeated ticks, ticks going backwards (unless allowed).
    """
    tk, arr = as_pairs(ticks, arrival_s, "arrival")
    est = ArrivalDejitter(tick_hz, half_life_s=half_life_s, k=k, allow_resets=allow_resets)
    times = est.update(tk, arr)
    base = est.model
    resid = arr - times
    segs = [
        ClockSegment(
            epoch=s.epoch,
            tick_start=s.tick_start,
            tick_end=s.tick_end,
            origin=s.origin,
            offset_s=s.offset_s,
            rate=s.rate,
            n=s.n,
            jitter_s=robust_sd(resid[(tk >= s.tick_start) & (tk <= s.tick_end)]) or s.jitter_s,
            rms_s=s.rms_s,
        )
        for s in base.segments
    ]
    model = ClockModel(tick_hz, segs, base.events, residuals=resid, method="arrivals")
    return DejitterResult(times_s=times, model=model)
