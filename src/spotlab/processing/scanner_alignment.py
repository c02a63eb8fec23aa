"""Several scanners in one frame, from a rigid object they all see (issue 18).

Each scanner reports 3-D in its own frame (:mod:`spotlab.reconstruction.scanner`).
A static rigid object with markers of known codes (an L-frame on a stand) seen by
two units gives, in each frame, the object's marker positions (the median over the
frames of a recording); the least-squares rigid motion between them
(:func:`~spotlab.reconstruction.rigid.rigid_fit`, with the reflection guard) carries
the second unit's trajectories into the first unit's frame:
``p_a = R p_b + t``. :func:`align_pairs` fits the same motion to the positions both
units saw at the same instants (a moving object too), once they share a time base
(:func:`points_at`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from spotlab.processing.errors import InputError
from spotlab.reconstruction.rigid import rigid_fit

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class Alignment:
    """A rigid motion from one scanner's frame into another's.

    Attributes
    ----------
    R : ndarray, shape (3, 3)
        Rotation, det +1.
    t : ndarray, shape (3,)
        Translation (mm).
    rms : float
        RMS distance of the reference markers after the fit (mm).
    labels : tuple of str
        The reference markers used.
    pairs : int
        Point pairs the fit used (:func:`align_pairs`), or the fewest frames a still
        marker's mean position was taken over (:func:`align_still`; 0 for medians).
    method : str
        ``medians`` (:func:`align_scanners`), ``still`` or ``pairs``.
    """

    R: F64
    t: F64
    rms: float
    labels: tuple[str, ...]
    pairs: int = 0
    method: str = "medians"

    def apply(self, points: F64) -> F64:
        """Points (..., 3) of the moved unit's frame in the reference unit's frame."""
        return points @ self.R.T + self.t


def reference_positions(points: F64, labels: Sequence[str], wanted: Sequence[str]) -> F64:
    """Median position (P, 3) of each ``wanted`` marker over the frames; NaN if never seen.

    Parameters
    ----------
    points : ndarray, shape (F, M, 3)
        A scanner's trajectories (mm), NaN where missing.
    labels : sequence of str, length M
        Their marker codes.
    wanted : sequence of str
        The reference object's marker codes.
    """
    out = np.full((len(wanted), 3), np.nan)
    for i, code in enumerate(wanted):
        if code in labels:
            column = points[:, list(labels).index(code)]
            seen = np.isfinite(column).all(axis=1)
            if seen.any():
                out[i] = np.median(column[seen], axis=0)
    return out


def align_scanners(
    points_a: F64,
    labels_a: Sequence[str],
    points_b: F64,
    labels_b: Sequence[str],
    reference: Sequence[str],
) -> Alignment:
    """The rigid motion carrying scanner B's frame into scanner A's.

    Raises
    ------
    InputError
        When fewer than 3 reference markers are seen by both units, or they are
        collinear; the message names the markers missing.
    """
    ref_a = reference_positions(points_a, labels_a, reference)
    ref_b = reference_positions(points_b, labels_b, reference)
    both = np.asarray(np.isfinite(ref_a).all(axis=1) & np.isfinite(ref_b).all(axis=1))
    if both.sum() < 3:
        missing = [c for c, ok in zip(reference, both.tolist(), strict=True) if not ok]
        raise InputError(
            f"aligning scanners needs 3 reference markers seen by both; not seen by both: "
            f"{', '.join(missing)}"
        )
    R, t, rms = rigid_fit(ref_b[both], ref_a[both][None])
    if not np.isfinite(rms[0]):
        raise InputError("the reference markers seen by both scanners are collinear")
    used = tuple(c for c, ok in zip(reference, both.tolist(), strict=True) if ok)
    return Alignment(R[0], t[0], float(rms[0]), used)


def points_at(times_s: F64, points: F64, at_s: F64, period_s: float) -> F64:
    """A unit's points interpolated at other instants, only between two scans in a row.

    Parameters
    ----------
    times_s : ndarray, shape (F,)
        Session time of each of the unit's frames (s), NaN where lost.
    points : ndarray, shape (F, M, 3)
        Its points (mm), NaN where missing.
    at_s : ndarray, shape (G,)
        The instants wanted (s), NaN allowed.
    period_s : float
        The unit's scan period: neighbours further apart than 1.5 periods (a lost scan,
        an occlusion) give NaN.

    Returns
    -------
    ndarray, shape (G, M, 3)
    """
    out = np.full((at_s.shape[0], *points.shape[1:]), np.nan)
    for m in range(points.shape[1]):
        ok = np.isfinite(points[:, m]).all(axis=1) & np.isfinite(times_s)
        t = times_s[ok]
        if t.shape[0] < 2:
            continue
        i = np.clip(np.searchsorted(t, at_s), 1, t.shape[0] - 1)
        near = (t[i] - t[i - 1]) < 1.5 * period_s
        for axis in range(3):
            v = np.interp(at_s, t, points[ok, m, axis], np.nan, np.nan)
            out[:, m, axis] = np.where(near, v, np.nan)
    return out


def align_pairs(a: F64, b: F64, codes: Sequence[str], trim: float = 4.0) -> Alignment:
    """The rigid motion carrying unit B's points onto unit A's, from simultaneous views.

    Parameters
    ----------
    a, b : ndarray, shape (F, P, 3)
        The shared markers ``codes`` as A and B saw them at the same instants (mm, B in
        its own frame), NaN where either did not.
    codes : sequence of str, length P
        Their colour codes.
    trim : float
        After a first fit, pairs further than ``trim`` times the median distance (at
        least 1 mm) are left out and the motion fitted again.

    Raises
    ------
    InputError
        Fewer than 3 markers seen by both units at a common instant, or collinear ones.
    """
    both = np.isfinite(a).all(axis=-1) & np.isfinite(b).all(axis=-1)
    used = np.asarray(both.any(axis=0), dtype=bool)
    seen: list[bool] = used.tolist()
    if used.sum() < 3:
        missing = [c for c, ok in zip(codes, seen, strict=True) if not ok]
        raise InputError(
            "aligning scanners needs 3 shared markers seen by both at common instants; "
            f"seen by both: {used.sum()} of {len(codes)}"
            + (f" (not: {', '.join(missing)})" if missing else "")
        )
    pa, pb = a[both], b[both]
    R, t, rms = rigid_fit(pb, pa[None])
    if not np.isfinite(rms[0]):
        raise InputError("the shared markers seen by both scanners are collinear")
    dist = np.linalg.norm(pb @ R[0].T + t[0] - pa, axis=1)
    keep = dist <= max(trim * float(np.median(dist)), 1.0)
    if keep.sum() >= 3 and not keep.all():
        R2, t2, rms2 = rigid_fit(pb[keep], pa[keep][None])
        if np.isfinite(rms2[0]):
            R, t, rms, pa = R2, t2, rms2, pa[keep]
    names = tuple(c for c, ok in zip(codes, seen, strict=True) if ok)
    return Alignment(R[0], t[0], float(rms[0]), names, int(pa.shape[0]), "pairs")


def still_markers(a: F64, b: F64, codes: Sequence[str], spread_mm: float = 3.0) -> list[int]:
    """Indices of the markers both units saw standing still (a static object's).

    Parameters
    ----------
    a, b : ndarray, shape (F, P, 3) and (G, P, 3)
        Each unit's view of the markers ``codes`` (mm), NaN where missing.
    spread_mm : float
        Largest standard deviation of a coordinate (mm) of a marker standing still
        (a scanner's noise at a few metres is well under 1 mm; a moving marker's is
        its motion).
    """
    out = []
    for i in range(len(codes)):
        ok = True
        for view in (a[:, i], b[:, i]):
            seen = view[np.isfinite(view).all(axis=1)]
            ok = ok and seen.shape[0] >= 10 and bool(np.all(np.std(seen, axis=0) < spread_mm))
        if ok:
            out.append(i)
    return out


def align_still(a: F64, b: F64, codes: Sequence[str], index: Sequence[int]) -> Alignment:
    """The rigid motion carrying unit B onto unit A from still markers' mean positions.

    The mean over each unit's frames (not the median: with an angle noise of half a
    count the median of quantised readings keeps the count's bias); no common time base
    is needed. ``index``: the markers of ``codes`` to use (:func:`still_markers`).
    """
    if len(index) < 3:
        raise InputError(f"aligning scanners needs 3 still markers, got {len(index)}")
    ref_a = np.stack([np.nanmean(a[:, i], axis=0) for i in index])
    ref_b = np.stack([np.nanmean(b[:, i], axis=0) for i in index])
    R, t, rms = rigid_fit(ref_b, ref_a[None])
    if not np.isfinite(rms[0]):
        raise InputError("the still markers seen by both scanners are collinear")
    seen = min(int(np.isfinite(v[:, i, 0]).sum()) for v in (a, b) for i in index)
    return Alignment(R[0], t[0], float(rms[0]), tuple(codes[i] for i in index), seen, "still")
