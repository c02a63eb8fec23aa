r"""Step detection in clock residuals: a windowed two-sample median changepoint test.

For each boundary b between pairs b - 1 and b, the statistic is

.. math:: s_b = \operatorname{med}(r_b, \dots, r_{b+w-1})
              - \operatorname{med}(r_{b-w}, \dots, r_{b-1}),

with r the residuals of the pairs about a line of the median rate over pairs N/8 apart
(robust to a few steps). A boundary is a step where :math:`|s_b| > \max(k \sigma,
s_{min})`, :math:`\sigma` the jitter estimated from first differences of r (robust SD
divided by sqrt 2). Medians make a single outlier (one late edge) invisible; a run of
boundaries above threshold is one step, placed at the largest single jump in the run.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from numpy.lib.stride_tricks import sliding_window_view

from spotlab.acquisition.clocks.linefit import robust_sd

I64 = npt.NDArray[np.int64]
F64 = npt.NDArray[np.float64]


def median_rate(ticks: I64, ref_s: F64, lag: int | None = None) -> float:
    """Median rate over pairs ``lag`` apart, s per tick; inputs shape (N,).

    Rates between neighbours are quantised by the tick (one tick in a 10 ms frame is
    100 ppm); over ``lag`` pairs (default N // 8) the quantisation shrinks ``lag`` times,
    while only the pairs that straddle a step (a fraction ``lag / N`` per step) are
    spoiled, which the median ignores.
    """
    n = ticks.size
    lag = max(1, n // 8) if lag is None else max(1, min(int(lag), n - 1))
    dt = (ticks[lag:] - ticks[:-lag]).astype(np.float64)
    return float(np.median((ref_s[lag:] - ref_s[:-lag]) / dt))


def difference_jitter(residuals: F64) -> float:
    """Jitter of white residuals from their first differences, s: robust SD / sqrt(2)."""
    return robust_sd(np.diff(residuals)) / np.sqrt(2.0)


def find_steps(
    ticks: I64,
    ref_s: F64,
    *,
    k: float = 8.0,
    window: int = 16,
    min_side: int = 3,
    min_step_s: float = 0.0,
    floor_s: float = 0.0,
) -> list[int]:
    """Indices where a new clock segment starts (steps between pair i - 1 and i).

    Parameters
    ----------
    ticks : ndarray of int64, shape (N,)
        Strictly increasing device ticks.
    ref_s : ndarray of float64, shape (N,)
        Reference times, s.
    k : float
        Threshold in jitters.
    window : int
        Pairs on each side of a boundary in the medians.
    min_side : int
        Fewest pairs on each side for a boundary to be tested; steps closer than this to
        either end are not detected (the robust line fit treats those pairs as outliers).
    min_step_s : float
        Smallest step reported, s.
    floor_s : float
        Smallest jitter assumed, s (the tick rounding SD: with exact data the measured
        jitter can be 0, which would make every boundary a step).

    Returns
    -------
    list of int
        Sorted indices i (1 <= i < N): pair i is the first of a new segment.
    """
    n = ticks.size
    if n < 2 * min_side:
        return []
    rate = median_rate(ticks, ref_s)
    r = ref_s - ref_s[0] - rate * (ticks - ticks[0]).astype(np.float64)
    sigma = difference_jitter(r)
    threshold = max(k * max(sigma, floor_s), min_step_s, 1e-15)
    w = max(1, min(window, n // 2))
    pad = np.full(w, np.nan)
    padded = np.concatenate([pad, r, pad])
    # windows[j] = padded[j : j + w]; boundary b: before = r[b-w:b] = windows[b],
    # after = r[b:b+w] = windows[b + w]
    windows = sliding_window_view(padded, w)
    b = np.arange(1, n)
    before = windows[b]
    after = windows[b + w]
    counts_before = np.minimum(b, w)
    counts_after = np.minimum(n - b, w)
    testable = (counts_before >= min_side) & (counts_after >= min_side)
    stat = np.zeros(b.size)
    if np.any(testable):
        stat[testable] = np.nanmedian(after[testable], axis=1) - np.nanmedian(
            before[testable], axis=1
        )
    above = testable & (np.abs(stat) > threshold)
    if not np.any(above):
        return []
    jumps = np.abs(np.diff(r))  # jumps[b - 1] = r[b] - r[b - 1]
    steps: list[int] = []
    edges = np.flatnonzero(np.diff(np.concatenate([[0], above.astype(np.int8), [0]])))
    for start, stop in zip(edges[::2], edges[1::2], strict=True):
        run = b[start:stop]
        same_sign = np.sign(stat[start:stop]) == np.sign(
            stat[start + np.argmax(np.abs(stat[start:stop]))]
        )
        cand = run[same_sign]
        steps.append(int(cand[np.argmax(jumps[cand - 1])]))
    return sorted(set(steps))
