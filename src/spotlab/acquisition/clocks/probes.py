r"""Clock models from NTP-style probe exchanges between host and device.

The host sends a probe at host time :math:`t_0`, the device receives it at device time
:math:`t_1` and answers at :math:`t_2`, the host receives the answer at :math:`t_3`:

.. math:: \text{rtt} = (t_3 - t_0) - (t_2 - t_1), \qquad
          \text{offset} = \frac{(t_1 - t_0) + (t_2 - t_3)}{2},

so the device midpoint :math:`(t_1 + t_2)/2` is paired with the host midpoint
:math:`(t_0 + t_3)/2`. The pairing is exact when the two one-way delays are equal;
an asymmetry biases the offset by half the difference of the delays, and no exchange
can observe it. Probes that met queueing delay have a long round trip, so, as liblsl
does (time_receiver.cpp: 8 probes every 2 s, the minimum-round-trip offset kept when at
least 6 return; see shared/research/protocols.md section 1.4), only the probe with the
smallest round trip of each window is kept; the kept pairs are fitted for offset and
drift with the robust piecewise fit of :mod:`~spotlab.acquisition.clocks.pairs`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from spotlab.acquisition.clocks.model import ClockModel
from spotlab.acquisition.clocks.pairs import as_pairs, fit_pairs
from spotlab.core.errors import ClockError

I64 = npt.NDArray[np.int64]
F64 = npt.NDArray[np.float64]


@dataclass(frozen=True)
class ProbePairs:
    """Midpoint pairs of probe exchanges.

    Attributes
    ----------
    ticks : ndarray of int64, shape (N,)
        Device midpoint, ticks (rounded down; the half tick moved to ``host_s``).
    host_s : ndarray of float64, shape (N,)
        Host midpoint, s.
    rtt_s : ndarray of float64, shape (N,)
        Round trip minus the device's turnaround, s.
    """

    ticks: I64
    host_s: F64
    rtt_s: F64


def probe_pairs(
    t0_s: npt.ArrayLike,
    t1_ticks: npt.ArrayLike,
    t2_ticks: npt.ArrayLike,
    t3_s: npt.ArrayLike,
    tick_hz: float,
) -> ProbePairs:
    """Midpoint pairs and round trips of probe exchanges, all shapes (N,).

    Parameters
    ----------
    t0_s, t3_s : array_like of float
        Host send and host receive times, s.
    t1_ticks, t2_ticks : array_like of int
        Device receive and device send times, ticks.
    tick_hz : float
        Nominal device tick rate, Hz (converts the turnaround to seconds).

    Raises
    ------
    ClockError
        Fewer than 3 exchanges, NaN, shapes that differ, an answer received before its
        probe was sent, a device that answers before it receives.
    """
    if not (np.isfinite(tick_hz) and tick_hz > 0):
        raise ClockError(f"tick rate must be finite and positive, got {tick_hz}")
    t1, t0 = as_pairs(t1_ticks, t0_s, "host send")
    t2, t3 = as_pairs(t2_ticks, t3_s, "host receive")
    if t1.shape != t2.shape:
        raise ClockError(f"t1 and t2 differ in shape: {t1.shape} and {t2.shape}")
    if np.any(t3 < t0):
        i = int(np.flatnonzero(t3 < t0)[0])
        raise ClockError(f"probe {i} was answered before it was sent (t3 < t0)")
    turn = t2 - t1
    if np.any(turn < 0):
        i = int(np.flatnonzero(turn < 0)[0])
        raise ClockError(f"device answered probe {i} before receiving it (t2 < t1)")
    rtt = (t3 - t0) - turn / tick_hz
    mid = t1 + turn // 2
    host = 0.5 * (t0 + t3) - 0.5 * (turn % 2) / tick_hz
    return ProbePairs(ticks=np.asarray(mid, dtype=np.int64), host_s=host, rtt_s=rtt)


def min_rtt_per_window(
    pairs: ProbePairs, t0_s: npt.ArrayLike, window_s: float = 2.0, min_probes: int = 1
) -> npt.NDArray[np.intp]:
    """Index of the smallest-round-trip exchange in each window of host send time.

    Parameters
    ----------
    pairs : ProbePairs
        From :func:`probe_pairs`.
    t0_s : array_like, shape (N,)
        Host send times, s (windows of ``window_s`` from the first).
    window_s : float
        Window length, s (liblsl: one burst of 8 probes every 2 s).
    min_probes : int
        Windows with fewer exchanges are skipped (liblsl wants 6 of 8).

    Returns
    -------
    ndarray of intp, shape (W,)
        Indices in increasing order of window.
    """
    if not window_s > 0 or min_probes < 1:
        raise ClockError("window_s must be > 0 and min_probes >= 1")
    t0 = np.asarray(t0_s, dtype=np.float64)
    win = np.floor((t0 - t0[0]) / window_s).astype(np.int64)
    order = np.lexsort((pairs.rtt_s, win))
    first = np.concatenate([[True], np.diff(win[order]) != 0])
    starts = np.flatnonzero(first)
    counts = np.diff(np.concatenate([starts, [order.size]]))
    keep = starts[counts >= min_probes]
    return np.sort(order[keep])


def fit_probes(
    t0_s: npt.ArrayLike,
    t1_ticks: npt.ArrayLike,
    t2_ticks: npt.ArrayLike,
    t3_s: npt.ArrayLike,
    tick_hz: float,
    *,
    window_s: float = 2.0,
    min_probes: int = 1,
    allow_resets: bool = False,
    k: float = 8.0,
) -> ClockModel:
    """Clock model (device ticks to host seconds) from probe exchanges.

    Parameters
    ----------
    t0_s, t1_ticks, t2_ticks, t3_s, tick_hz
        As in :func:`probe_pairs`.
    window_s, min_probes
        As in :func:`min_rtt_per_window`.
    allow_resets, k
        As in :func:`~spotlab.acquisition.clocks.pairs.fit_pairs`.

    Returns
    -------
    ClockModel
        ``method="probes"``; residuals are those of the kept (minimum round trip)
        exchanges.

    Raises
    ------
    ClockError
        Bad exchanges (see :func:`probe_pairs`), fewer than 3 windows kept.
    """
    pairs = probe_pairs(t0_s, t1_ticks, t2_ticks, t3_s, tick_hz)
    keep = min_rtt_per_window(pairs, t0_s, window_s, min_probes)
    if keep.size < 3:
        raise ClockError(
            f"only {keep.size} probe windows with >= {min_probes} exchanges; need at least 3"
        )
    return fit_pairs(
        pairs.ticks[keep],
        pairs.host_s[keep],
        tick_hz,
        allow_resets=allow_resets,
        k=k,
        window=8,
        method="probes",
    )
