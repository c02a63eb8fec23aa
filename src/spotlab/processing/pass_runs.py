"""Runs of one identification pass's labels, and the runs the other pass refutes.

A pass labels a marker in *runs*: frames in a row in which its point follows one path.
A run ends at a gap, or where the pass moves the label onto another point without one
(its point departs from its own constant-velocity path by more than ``jump_mm``): a
pass that took a marker wrongly and later took it again rightly does so at a gap or at
such a jump. Two passes over the same frames check each other run by run
(:func:`refuted_labels`), before :func:`~spotlab.processing.identification_passes.join_passes`
joins them frame by frame: a wrong run that one pass kept for many frames, with the
other pass silent on most of them, counts against that marker as a whole there, and
can make it look as if one pass followed another identity throughout.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from spotlab.reconstruction.identification import MarkerModel

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]

#: Jump (mm) off a label's constant-velocity path that ends a run, for a model
#: without a learnt rigid tolerance (segments given by name).
JUMP_MM = 20.0


def jump_mm(model: MarkerModel) -> float:
    """Departure (mm) from a label's own path that ends a run: the model's rigid
    tolerance when it was learnt (the spread its distances allow a marker), else
    :data:`JUMP_MM`."""
    return float(model.tolerance_mm) if model.tolerance_mm is not None else JUMP_MM


def label_runs(points: FloatArray, jump: float) -> IntArray:
    """Run number of each labelled marker-frame, -1 where not labelled.

    Parameters
    ----------
    points : ndarray, shape (F, M, 3)
        One pass's labelled positions (mm), frames in recording order, NaN where not
        labelled.
    jump : float
        A label whose point departs from the straight line through its two previous
        points by more than this (mm) starts a new run.

    Returns
    -------
    ndarray of int, shape (F, M)
        Numbers unique over all markers; a run is frames in a row of one marker.
    """
    F, M, _ = points.shape
    has = np.isfinite(points[..., 0])
    bend = np.zeros((F, M))
    if F > 2:
        with np.errstate(invalid="ignore"):
            bend[2:] = np.linalg.norm(points[2:] - 2 * points[1:-1] + points[:-2], axis=-1)
    bent = np.nan_to_num(bend, nan=0.0) > jump
    # the frame after a jump is predicted from a point before it: not a jump of its own
    bent[1:] &= ~bent[:-1]
    after = np.zeros((F, M), dtype=bool)
    after[1:] = has[:-1]
    starts = has & ~(after & ~bent)
    number = np.cumsum(starts.ravel(order="F")).reshape((F, M), order="F") - 1
    return np.where(has, number, -1).astype(np.int64)


def refuted_labels(
    points: FloatArray, other: FloatArray, agree_mm: float, jump: float
) -> BoolArray:
    """Labels of ``points`` in runs the other pass ``other`` refutes.

    A run is *confirmed* when the other pass puts the marker within ``agree_mm`` of it
    on more frames than it puts it elsewhere. A run that is not confirmed is *refuted*
    when a confirmed run of the other pass contradicts it (puts the marker elsewhere in
    a frame, or gives its point to another marker), or when the other pass contradicts
    it and it adjoins, without a gap, a confirmed run of its own pass (the pass moved the
    label onto the point the other pass confirms). Then, once: a run of the other pass
    that differs from this one only where the labels just refuted lie is *cleared*, and
    refutes as a confirmed run does (a pass that exchanged two markers for a few frames
    made one mistake: when one half is refuted, the other half goes with it, refuted by
    the labels the first half stood against).
    Two passes that agree on a wrong identity more than they disagree confirm it: this
    removes labels only where one pass's labels are borne out by the other.

    Parameters
    ----------
    points, other : ndarray, shape (F, M, 3)
        The two passes' labelled positions (mm), frames in recording order.
    agree_mm : float
        Two passes agree on a marker-frame when their points are this close.
    jump : float
        See :func:`label_runs`.

    Returns
    -------
    ndarray of bool, shape (F, M)
    """
    both = np.isfinite(points[..., 0]) & np.isfinite(other[..., 0])
    dist = np.where(both, np.linalg.norm(np.nan_to_num(points - other), axis=-1), np.inf)
    agree = both & (dist <= agree_mm)
    differ = both & (dist > agree_mm)
    own, theirs = label_runs(points, jump), label_runs(other, jump)
    n_own, n_theirs = max(int(own.max()) + 1, 1), max(int(theirs.max()) + 1, 1)
    confirmed_own = _confirmed(own, agree, differ, n_own)
    confirmed_theirs = _confirmed(theirs, agree, differ, n_theirs)
    in_confirmed = (theirs >= 0) & confirmed_theirs[np.maximum(theirs, 0)]
    refuted = _refuted_runs(
        points, other, own, confirmed_own, in_confirmed, agree, differ, agree_mm
    )
    # (c) a second look: a run of the other pass that differs from this pass only where
    # its labels were just refuted is cleared of that doubt, and refutes as a confirmed
    # run does (two labels exchanged are one mistake: one half refuted, the other
    # contradicted by the labels the refuted half stood against)
    at_refuted = (own >= 0) & refuted[np.maximum(own, 0)]
    labelled = theirs >= 0
    n_differ = np.bincount(theirs[differ & labelled], minlength=n_theirs)
    n_open = np.bincount(theirs[differ & labelled & ~at_refuted], minlength=n_theirs)
    cleared = (n_differ > 0) & (n_open == 0)
    in_trusted = in_confirmed | (labelled & cleared[np.maximum(theirs, 0)])
    if (in_trusted != in_confirmed).any():
        refuted = _refuted_runs(
            points, other, own, confirmed_own, in_trusted, agree, differ, agree_mm
        )
    return (own >= 0) & refuted[np.maximum(own, 0)]


def _refuted_runs(
    points: FloatArray,
    other: FloatArray,
    own: IntArray,
    confirmed_own: BoolArray,
    in_trusted: BoolArray,
    agree: BoolArray,
    differ: BoolArray,
    agree_mm: float,
) -> BoolArray:
    """(n,) runs ``own`` of ``points`` refuted by the other pass's labels ``in_trusted``
    (F, M) (rules (a) and (b) of :func:`refuted_labels`)."""
    n_own = len(confirmed_own)
    contradicted = np.bincount(own[differ], minlength=n_own) > 0
    # (a) contradicted by a confirmed run of the other pass: the marker elsewhere, or
    # its point given to another marker
    doubtful = (own >= 0) & ~confirmed_own[np.maximum(own, 0)] & ~agree
    hit = (differ & in_trusted) | (
        doubtful & _named_otherwise(points, other, in_trusted, doubtful, agree_mm)
    )
    by_confirmed = np.zeros(n_own, dtype=bool)
    by_confirmed[own[hit]] = True
    # (b) adjoining, without a gap, a confirmed run of its own pass
    adjoins = np.zeros(n_own, dtype=bool)
    cut = (own[1:] >= 0) & (own[:-1] >= 0) & (own[1:] != own[:-1])
    later, earlier = own[1:][cut], own[:-1][cut]
    adjoins[later[confirmed_own[earlier]]] = True
    adjoins[earlier[confirmed_own[later]]] = True
    return np.asarray(~confirmed_own & (by_confirmed | (contradicted & adjoins)))


def _confirmed(runs: IntArray, agree: BoolArray, differ: BoolArray, n: int) -> BoolArray:
    """(n,) runs on which the other pass agrees on more frames than it differs."""
    n_agree = np.bincount(runs[agree & (runs >= 0)], minlength=n)
    n_differ = np.bincount(runs[differ & (runs >= 0)], minlength=n)
    return np.asarray(n_agree > n_differ)


def _named_otherwise(
    points: FloatArray,
    other: FloatArray,
    trusted: BoolArray,
    asked: BoolArray,
    agree_mm: float,
    chunk: int = 512,
) -> BoolArray:
    """(F, M) labels of ``points`` (of those ``asked``) within ``agree_mm`` of a
    ``trusted`` label the other pass gives another marker in the same frame."""
    F, M, _ = points.shape
    out = np.zeros((F, M), dtype=bool)
    others = ~np.eye(M, dtype=bool)
    frames = np.flatnonzero(asked.any(axis=1))
    for a in range(0, frames.size, chunk):
        f = frames[a : a + chunk]
        p, q = points[f], other[f]
        with np.errstate(invalid="ignore"):
            d = np.linalg.norm(p[:, :, None, :] - q[:, None, :, :], axis=-1)
        close = (d <= agree_mm) & others & trusted[f, None, :]
        out[f] = close.any(axis=2) & asked[f]
    return out
