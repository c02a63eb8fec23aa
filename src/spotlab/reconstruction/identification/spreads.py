"""Distance spreads of labelled trajectories: what :meth:`.model.MarkerModel.infer` learns from.

The spread of a marker pair is the range (max - min, mm) of its distance over a trial.
From the spreads come the rigid tolerance of a trial (:func:`rigid_tolerance`), the
check that a trial moves enough to tell segments apart (:func:`check_motion`) and the
extra links of markers on no cluster (:func:`least_varying`).
"""

from __future__ import annotations

import warnings

import numpy as np
from numpy.typing import NDArray

from spotlab.core.errors import ReconstructionError

__all__ = [
    "check_motion",
    "distance_range",
    "least_varying",
    "rigid_tolerance",
    "robust_range",
]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]

#: Chosen rigid tolerance: this many times the typical spread of a marker's second most
#: rigid partner, and at least ``TOLERANCE_FLOOR_MM``.
TOLERANCE_FACTOR = 2.0
TOLERANCE_FLOOR_MM = 2.0
#: A trial moves when at least this share of marker pairs varies by more than
#: ``MOVING_TOLERANCES`` rigid tolerances.
MOVING_SHARE = 0.25
MOVING_TOLERANCES = 4.0
#: Robust ranges: quantiles of this share at each end, and the largest overshoot of the
#: extremes beyond them kept (``ROBUST_PAD_MM`` plus this share of the inner range).
ROBUST_SHARE = 0.05
ROBUST_PAD_MM = 20.0
ROBUST_PAD_SHARE = 1.0
#: Frames (evenly spaced) the quantiles of :func:`robust_range` are taken from, at most.
ROBUST_FRAMES = 4000


def distance_range(X: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Smallest and largest distance (M, M) of every marker pair over the frames of ``X``
    (F, M, 3) where both are present; NaN for pairs never seen together."""
    lo = np.full(X.shape[1:2] * 2, np.inf)
    hi = np.full(X.shape[1:2] * 2, -np.inf)
    for start in range(0, X.shape[0], 256):  # (256, M, M) at a time
        D = np.linalg.norm(X[start : start + 256, :, None] - X[start : start + 256, None], axis=-1)
        D = np.where(np.isfinite(D), D, np.nan)
        with np.errstate(invalid="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN pairs
            lo = np.fmin(lo, np.nanmin(D, axis=0))
            hi = np.fmax(hi, np.nanmax(D, axis=0))
    never = ~np.isfinite(lo) | ~np.isfinite(hi)
    return np.where(never, np.nan, lo), np.where(never, np.nan, hi)


def robust_range(X: FloatArray) -> tuple[FloatArray, FloatArray]:
    """:func:`distance_range` without the glitches of a file.

    A labelled trajectory may jump for a few frames (a marker written as (0, 0, 0)
    where it was missing, a reconstruction glitch: metres in one frame); the smallest
    and largest distances then hold the glitch, not the body. Here a distance lying
    beyond the ``ROBUST_SHARE`` (5 %) quantile at either end by more than
    ``ROBUST_PAD_MM`` plus ``ROBUST_PAD_SHARE`` of the range between the two quantiles
    is a glitch and left out; the range is the smallest and largest of the others. A
    smooth trial keeps its ranges exactly, a jump of metres is left out.

    Parameters
    ----------
    X : ndarray, shape (F, M, 3)
        Trajectories (mm), NaN where missing.

    Returns
    -------
    lo, hi : ndarray, shape (M, M)
        Smallest and largest distance of every pair, glitches left out; NaN for pairs
        never seen together.
    """
    F, M = X.shape[:2]
    sample = X[np.unique(np.linspace(0, F - 1, min(F, ROBUST_FRAMES)).round().astype(int))]
    q_lo = np.full((M, M), np.nan)
    q_hi = np.full((M, M), np.nan)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN pairs
        for m in range(M):
            D = np.linalg.norm(sample[:, m, None] - sample, axis=-1)  # (F', M)
            q = np.nanquantile(D, [ROBUST_SHARE, 1.0 - ROBUST_SHARE], axis=0)
            q_lo[m], q_hi[m] = q[0], q[1]
    pad = ROBUST_PAD_MM + ROBUST_PAD_SHARE * (q_hi - q_lo)
    low, high = q_lo - pad, q_hi + pad  # NaN for pairs never seen: nothing kept
    lo = np.full((M, M), np.inf)
    hi = np.full((M, M), -np.inf)
    for start in range(0, F, 256):  # (256, M, M) at a time
        D = np.linalg.norm(X[start : start + 256, :, None] - X[start : start + 256, None], axis=-1)
        with np.errstate(invalid="ignore"):
            D = np.where((D >= low) & (D <= high), D, np.nan)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            lo = np.fmin(lo, np.nanmin(D, axis=0))
            hi = np.fmax(hi, np.nanmax(D, axis=0))
    never = ~np.isfinite(lo) | ~np.isfinite(hi)
    return np.where(never, np.nan, lo), np.where(never, np.nan, hi)


def rigid_tolerance(spread: FloatArray) -> float:
    """The rigid tolerance (mm) of a trial from its distance spreads.

    Parameters
    ----------
    spread : ndarray, shape (M, M)
        Spread (max - min, mm) of the distance of every marker pair over the trial;
        large for pairs never seen together.

    Returns
    -------
    float
        ``TOLERANCE_FACTOR`` (2) times the median over the markers of each marker's
        second-smallest spread, and at least ``TOLERANCE_FLOOR_MM`` (2 mm).

    Notes
    -----
    A marker of a cluster of three has two partners on its segment, so its
    second-smallest spread is that of a pair on one segment: skin sliding over bone
    and the lab's noise (a few mm for skin markers, ~0 for a rigid plate or the
    simulator's truth). Pairs across a joint vary by tens to hundreds of mm as the
    joint flexes. The median over the markers is the typical within-segment spread,
    robust to the markers near joints or alone on their segment, whose second-smallest
    spread is a cross-joint one. Twice that leaves room for frames the model never
    saw (a range seen on part of a trial only grows on the rest) while staying well
    below the cross-joint spreads; the floor keeps exactly rigid data (the
    simulator's) at the tolerance its labelling was measured with.
    """
    S = np.array(spread, dtype=np.float64)
    if S.shape[0] < 3:
        return TOLERANCE_FLOOR_MM
    np.fill_diagonal(S, np.inf)
    second = np.sort(S, axis=1)[:, 1]
    return float(max(TOLERANCE_FLOOR_MM, TOLERANCE_FACTOR * np.median(second)))


def check_motion(spread: FloatArray, tolerance_mm: float) -> None:
    """Raise a ReconstructionError for a trial that hardly moves: fewer than
    ``MOVING_SHARE`` of the marker pairs vary by ``MOVING_TOLERANCES`` tolerances."""
    M = spread.shape[0]
    if M < 3:
        return
    i, j = np.triu_indices(M, 1)
    share = float(np.mean(spread[i, j] > MOVING_TOLERANCES * tolerance_mm))
    if share < MOVING_SHARE:
        raise ReconstructionError(
            f"the trial hardly moves: {100 * share:.0f} % of marker pairs change their "
            f"distance by more than {MOVING_TOLERANCES * tolerance_mm:.0f} mm, every marker "
            "looks rigid; learn from a trial in which the segments move through their range"
        )


def least_varying(
    lo: FloatArray, hi: FloatArray, owner: NDArray[np.intp], a: IntArray, b: IntArray,
    keep: NDArray[np.bool_], apart: NDArray[np.bool_], min_links: int,
) -> NDArray[np.bool_]:  # fmt: skip
    """Extra links (pairs ``a, b``) giving each marker on no segment ``min_links`` links:
    its least varying partners not yet linked (pairs never seen together excluded)."""
    M = lo.shape[0]
    extra = np.zeros(a.size, dtype=bool)
    spread = hi[a, b] - lo[a, b]
    usable = apart & np.isfinite(spread)
    count = np.bincount(a[keep], minlength=M) + np.bincount(b[keep], minlength=M)
    for m in np.flatnonzero((owner < 0) & (count < min_links)):
        mine = np.flatnonzero(usable & ~keep & ~extra & ((a == m) | (b == m)))
        mine = mine[np.argsort(spread[mine])][: min_links - count[m]]
        extra[mine] = True
        count[a[mine]] += 1
        count[b[mine]] += 1
    return extra
