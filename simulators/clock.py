"""A device's own clock, seen from the world clock every simulator on the machine shares.

The world clock is ``time.monotonic_ns()``. A device has an oscillator that
runs ``drift_ppm`` fast or slow, a counter that starts at ``offset_s`` when the
device powers up and may jump by scheduled steps, and a trigger whose timing
scatters by ``jitter_s`` RMS around the counter's idea of time.

Three time bases appear:

* world ns — ``time.monotonic_ns()``;
* oscillator seconds — elapsed seconds as the device's crystal counts them since
  power-up, ``osc = (world - epoch) * (1 + drift)``; frame pacing runs on it;
* device µs — the timestamp counter, ``offset + osc + steps``, in µs, unwrapped.
  The wire carries it modulo 2**32 (the frame encoder wraps it).
"""

from __future__ import annotations

import time
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

F64 = npt.NDArray[np.float64]
# Rounding guard: (offset + osc) * 1e6 can land a hair below a whole tick.
_EPS_US = 1e-4


class DeviceClock:
    """Clock of one simulated device.

    Parameters
    ----------
    offset_s : float, optional
        Device time in seconds at power-up (the counter's start value).
    drift_ppm : float, optional
        Oscillator error in parts per million; positive runs fast.
    jitter_s : float, optional
        RMS scatter, in seconds, of the true instant a frame is taken around
        the instant its timestamp names (seeded, Gaussian).
    steps : sequence of (float, float), optional
        ``(at_s, delta_s)`` pairs: at ``at_s`` world seconds after power-up the
        counter jumps by ``delta_s`` seconds (frame pacing is not affected).
    seed : int, optional
        Seed of the jitter.
    epoch_ns : int, optional
        World time (``time.monotonic_ns()``) of power-up; default: now.

    Notes
    -----
    ``device_us(w) = 1e6 * (offset_s + osc(w) + sum of steps due by w)`` with
    ``osc(w) = (w - epoch_ns) / 1e9 * (1 + drift_ppm / 1e6)``.
    """

    def __init__(
        self,
        offset_s: float = 0.0,
        drift_ppm: float = 0.0,
        jitter_s: float = 0.0,
        steps: Sequence[tuple[float, float]] = (),
        seed: int = 0,
        epoch_ns: int | None = None,
    ) -> None:
        if jitter_s < 0:
            raise ValueError(f"clock jitter must be >= 0 s, got {jitter_s}")
        if not -1e5 < drift_ppm < 1e5:
            raise ValueError(f"clock drift of {drift_ppm} ppm is not a clock")
        self.offset_s = float(offset_s)
        self.drift_ppm = float(drift_ppm)
        self.jitter_s = float(jitter_s)
        self.epoch_ns = time.monotonic_ns() if epoch_ns is None else int(epoch_ns)
        self.seed = int(seed)
        self._rate = 1.0 + self.drift_ppm * 1e-6
        ordered = sorted((float(at), float(delta)) for at, delta in steps)
        #: The steps as given, ``(at_s, delta_s)`` in time order.
        self.steps = tuple(ordered)
        # Steps in oscillator seconds, with the running sum of all steps up to each one.
        self._step_osc = np.array([at * self._rate for at, _ in ordered], dtype=np.float64)
        self._step_sum = np.cumsum([delta for _, delta in ordered], dtype=np.float64)
        self._rng = np.random.default_rng(np.random.SeedSequence([seed, 0xC10C]))

    # -- world <-> oscillator ---------------------------------------------
    def osc_s(self, world_ns: int) -> float:
        """Oscillator seconds since power-up at world time ``world_ns``."""
        return (world_ns - self.epoch_ns) * 1e-9 * self._rate

    def world_ns(self, osc_s: npt.ArrayLike) -> F64:
        """World time in ns (float, any shape) at which the oscillator reads ``osc_s``."""
        return self.epoch_ns + np.asarray(osc_s, dtype=np.float64) / self._rate * 1e9

    def world_ns_at(self, osc_s: float) -> int:
        """World time in whole ns (rounded up) at which the oscillator reads ``osc_s``."""
        return int(np.ceil(self.epoch_ns + osc_s / self._rate * 1e9))

    # -- oscillator -> counter ----------------------------------------------
    def steps_before(self, osc_s: float) -> float:
        """Sum of the counter steps due at or before oscillator time ``osc_s``, seconds."""
        if not self.steps:
            return 0.0
        i = int(np.searchsorted(self._step_osc, osc_s, side="right"))
        return float(self._step_sum[i - 1]) if i else 0.0

    def step_count(self, osc_s: float) -> int:
        """How many counter steps are due at or before oscillator time ``osc_s``."""
        if not self.steps:
            return 0
        return int(np.searchsorted(self._step_osc, osc_s, side="right"))

    def device_us_at_osc(self, osc_s: float) -> float:
        """Counter value in µs (unwrapped, fractional) at oscillator time ``osc_s``."""
        return (self.offset_s + osc_s + self.steps_before(osc_s)) * 1e6

    def device_us(self, world_ns: int) -> float:
        """Counter value in µs (unwrapped, fractional) at world time ``world_ns``."""
        return self.device_us_at_osc(self.osc_s(world_ns))

    def ticks(self, world_ns: int) -> int:
        """Whole device µs ticks (unwrapped; the wire takes them modulo 2**32)."""
        return int(np.floor(self.device_us(world_ns) + _EPS_US))

    def world_to_ticks(self, world_ns: npt.ArrayLike) -> npt.NDArray[np.int64]:
        """Vectorised :meth:`ticks`, shape preserved."""
        w = np.asarray(world_ns, dtype=np.float64)
        osc = (w - self.epoch_ns) * 1e-9 * self._rate
        idx = np.searchsorted(self._step_osc, osc, side="right")
        steps = np.concatenate([[0.0], self._step_sum])[idx]
        return np.floor((self.offset_s + osc + steps) * 1e6 + _EPS_US).astype(np.int64)

    def ticks_to_world_ns(self, ticks: npt.ArrayLike) -> F64:
        """World ns at which the counter reads ``ticks`` (unwrapped µs), assuming no steps.

        With steps the counter is not monotonic in general; use this between steps only.
        """
        osc = np.asarray(ticks, dtype=np.float64) * 1e-6 - self.offset_s
        return self.world_ns(osc)

    # -- jitter ---------------------------------------------------------------
    def jitter(self) -> float:
        """The next trigger-jitter sample in seconds (0 when no jitter is set)."""
        if self.jitter_s == 0.0:
            return 0.0
        return float(self._rng.normal(0.0, self.jitter_s))

    def jitter_for(self, *key: int) -> float:
        """The trigger-jitter sample of the event named by ``key`` (e.g. stream, frame), s.

        A pure function of the seed and the key, so that another simulator given
        this clock's parameters (the lab wiring, :mod:`spotlab.simulators.lab`)
        reproduces the same instants.
        """
        if self.jitter_s == 0.0:
            return 0.0
        rng = np.random.default_rng([self.seed, 0xC10C, *(k & 0xFFFFFFFF for k in key)])
        return float(rng.normal(0.0, self.jitter_s))
