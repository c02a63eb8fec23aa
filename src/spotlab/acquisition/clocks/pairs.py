"""Fit a piecewise clock model to (device ticks, reference seconds) pairs.

The common back end of the edge, probe and XDF fits: split the pairs into counter
epochs where ticks go backwards (resets), find steps inside each epoch
(:func:`~spotlab.acquisition.clocks.steps.find_steps`, applied again inside each piece
until none is left), fit each segment with a Huber-robust line, and report the
discontinuities as events.
"""

from __future__ import annotations

import itertools

import numpy as np
import numpy.typing as npt

from spotlab.acquisition.clocks.linefit import LineFit, fit_line
from spotlab.acquisition.clocks.model import ClockEvent, ClockModel, ClockSegment
from spotlab.acquisition.clocks.steps import find_steps
from spotlab.core.errors import ClockError

I64 = npt.NDArray[np.int64]
F64 = npt.NDArray[np.float64]

#: Counter widths whose whole periods make a step a "wrap" event.
WRAP_BITS = (32, 16)
MIN_PAIRS = 3


def as_pairs(
    ticks: npt.ArrayLike, ref_s: npt.ArrayLike, what: str = "reference"
) -> tuple[I64, F64]:
    """Validated int64 ticks and float64 reference times, shape (N,) each.

    Raises
    ------
    ClockError
        Shapes that differ or are not 1-D, fewer than 3 pairs, NaN or infinite values,
        ticks that are not whole numbers.
    """
    tk = np.asarray(ticks)
    ref = np.asarray(ref_s, dtype=np.float64)
    if tk.ndim != 1 or ref.shape != tk.shape:
        raise ClockError(
            f"ticks and {what} times must be 1-D of equal length, got {tk.shape} and {ref.shape}"
        )
    if tk.size < MIN_PAIRS:
        raise ClockError(f"a clock fit needs at least {MIN_PAIRS} pairs, got {tk.size}")
    if tk.dtype.kind == "f":
        if not np.all(np.isfinite(tk)):
            raise ClockError(f"ticks hold NaN or infinite values (first at pair {_first_bad(tk)})")
        if np.any(tk != np.round(tk)):
            raise ClockError("ticks must be whole numbers")
    elif tk.dtype.kind not in "iu":
        raise ClockError(f"ticks must be integers, got dtype {tk.dtype}")
    if not np.all(np.isfinite(ref)):
        raise ClockError(
            f"{what} times hold NaN or infinite values (first at pair {_first_bad(ref)})"
        )
    return np.asarray(tk, dtype=np.int64), ref


def _first_bad(values: npt.NDArray[np.generic]) -> int:
    return int(np.flatnonzero(~np.isfinite(values.astype(np.float64)))[0])


def _segments_of(
    ticks: I64, ref: F64, k: float, window: int, min_step_s: float, floor_s: float
) -> list[int]:
    """Start indices of the segments of one epoch (always begins with 0)."""
    starts = [0]
    pending = [(0, ticks.size)]
    while pending:
        lo, hi = pending.pop()
        found = find_steps(
            ticks[lo:hi], ref[lo:hi], k=k, window=window, min_step_s=min_step_s, floor_s=floor_s
        )
        for i in found:
            starts.append(lo + i)
        cuts = [lo, *(lo + i for i in found), hi]
        if found:
            pending.extend((a, b) for a, b in itertools.pairwise(cuts) if b - a >= 6)
    return sorted(set(starts))


def event_kind(
    tick_jump: int, expected_ticks: float, tol_ticks: float, wrap_bits: tuple[int, ...] = WRAP_BITS
) -> str:
    """ "wrap" if the excess of a tick jump over the expected one is a whole number of
    counter periods (within ``tol_ticks``, and the period larger than 10 x the tolerance),
    else "step"."""
    excess = tick_jump - expected_ticks
    for bits in wrap_bits:
        period = float(1 << bits)
        cycles = round(excess / period)
        if period < 10.0 * tol_ticks:
            continue
        if cycles != 0 and abs(excess - cycles * period) <= tol_ticks:
            return "wrap"
    return "step"


def fit_pairs(
    ticks: npt.ArrayLike,
    ref_s: npt.ArrayLike,
    tick_hz: float,
    *,
    allow_resets: bool = False,
    k: float = 8.0,
    window: int = 16,
    min_step_s: float = 0.0,
    increasing_reference: bool = True,
    floor_s: float | None = None,
    wrap_bits: tuple[int, ...] = WRAP_BITS,
    method: str = "pairs",
) -> ClockModel:
    """Clock model from pairs of device ticks and reference times of the same instants.

    Parameters
    ----------
    ticks : array_like of int, shape (N,)
        Unwrapped device ticks, in acquisition order.
    ref_s : array_like of float, shape (N,)
        Reference (session) time of the same instants, s.
    tick_hz : float
        Nominal device tick rate, Hz.
    allow_resets : bool
        If True, ticks going backwards start a new epoch (a "reset" event); if False
        (default) they raise ClockError.
    k, window, min_step_s : see :func:`~spotlab.acquisition.clocks.steps.find_steps`.
    increasing_reference : bool
        Require the reference to advance at every pair (a timer that stopped or
        repeated raises ClockError).
    floor_s : float, optional
        Scale floor of the robust fit, s; default one tick / sqrt(12).
    wrap_bits : tuple of int
        Counter widths whose whole periods make a step a "wrap" event.
    method : str
        Name stored in the model.

    Returns
    -------
    ClockModel
        With the residuals of all pairs in input order.

    Raises
    ------
    ClockError
        Too few pairs (overall, or in an epoch after a reset), NaN, repeated ticks,
        ticks going backwards without ``allow_resets``, a reference that does not advance.
    """
    if not (np.isfinite(tick_hz) and tick_hz > 0):
        raise ClockError(f"tick rate must be finite and positive, got {tick_hz}")
    tk, ref = as_pairs(ticks, ref_s)
    if increasing_reference:
        stalled = np.flatnonzero(np.diff(ref) <= 0)
        if stalled.size:
            i = int(stalled[0]) + 1
            raise ClockError(
                f"reference time does not advance at pair {i} ({ref[i - 1]!r} -> {ref[i]!r} s): "
                "the reference stopped, repeated or went backwards"
            )
    dtk = np.diff(tk)
    if np.any(dtk == 0):
        i = int(np.flatnonzero(dtk == 0)[0]) + 1
        raise ClockError(f"ticks repeat at pair {i} ({tk[i]}): two frames with one timestamp")
    backwards = np.flatnonzero(dtk < 0) + 1
    if backwards.size and not allow_resets:
        i = int(backwards[0])
        raise ClockError(
            f"ticks go backwards at pair {i} ({tk[i - 1]} -> {tk[i]}): the device clock was "
            "reset or stepped back; pass allow_resets=True to fit a new epoch"
        )
    floor = (1.0 / tick_hz) / np.sqrt(12.0) if floor_s is None else float(floor_s)
    bounds = [0, *backwards.tolist(), tk.size]
    residuals = np.empty(tk.size)
    segments: list[ClockSegment] = []
    fits: list[tuple[LineFit, int, int]] = []
    events: list[ClockEvent] = []
    for epoch, (lo, hi) in enumerate(itertools.pairwise(bounds)):
        if hi - lo < MIN_PAIRS:
            raise ClockError(
                f"epoch {epoch} (pairs {lo}..{hi - 1}) has {hi - lo} pairs; a clock fit needs "
                f"at least {MIN_PAIRS}"
            )
        starts = [lo + s for s in _segments_of(tk[lo:hi], ref[lo:hi], k, window, min_step_s, floor)]
        for a, b in zip(starts, [*starts[1:], hi], strict=True):
            fit = fit_line(tk[a:b], ref[a:b], floor_s=floor)
            residuals[a:b] = fit.residuals
            res = fit.residuals
            segments.append(
                ClockSegment(
                    epoch=epoch,
                    tick_start=int(tk[a]),
                    tick_end=int(tk[b - 1]),
                    origin=fit.origin,
                    offset_s=fit.offset_s,
                    rate=fit.rate,
                    n=b - a,
                    jitter_s=fit.jitter_s,
                    rms_s=float(np.sqrt(np.mean(res**2))),
                    max_abs_s=float(np.max(np.abs(res))),
                )
            )
            fits.append((fit, a, b))
    for (prev, _, pb), (cur, ca, _) in itertools.pairwise(fits):
        seg_prev = segments[len(events)]
        seg_cur = segments[len(events) + 1]
        # device ticks each segment assigns to the reference instant of the new segment's
        # first pair; their difference is the jump of the device clock
        t_star = ref[ca]
        x_prev = prev.origin + (t_star - prev.offset_s) / prev.rate
        x_cur = cur.origin + (t_star - cur.offset_s) / cur.rate
        size_s = float((x_cur - x_prev) / tick_hz)
        if seg_cur.epoch != seg_prev.epoch:
            kind = "reset"
        else:
            expected = (ref[ca] - ref[pb - 1]) / prev.rate
            tol = max(20.0 * max(prev.jitter_s, cur.jitter_s) / prev.rate, 4.0)
            kind = event_kind(int(tk[ca] - tk[pb - 1]), expected, tol, wrap_bits)
        events.append(ClockEvent(kind=kind, at_tick=int(tk[ca]), size_s=size_s, index=ca))
    return ClockModel(tick_hz, segments, events, residuals=residuals, method=method)
