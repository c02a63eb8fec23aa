"""Labels from the marker model: cluster checks and identities by the smallest RMS fit.

Two jobs, both on the 3-D points of one frame:

* :func:`inconsistent_labels` checks labelled points against their segments: a marker
  whose distances to the other markers of its segment disagree with the model is
  unlabelled again, so a track that jumped to the wrong marker never keeps its label.
* :func:`assign_labels` gives labels to unlabelled points. A segment with three or more
  labelled points has a pose (least squares, :func:`rigid_fit`), so its missing markers
  are predicted and matched within ``tol_mm`` (re-identification after occlusion).
  Otherwise the candidates are enumerated with an interpretation tree (pairwise
  distances within ``tol_mm``), and among those with the most markers the identity with
  the smallest RMS fit is chosen (:func:`choose_identity`; Woltring & Huiskes 1990:
  "one may use the rms fitting error to decide between candidate solutions"). A choice
  whose runner-up is within ``margin_mm`` is ambiguous and not taken, and so are two
  clusters' best identities that take some of the same unlabelled points with RMS
  within ``margin_mm`` of each other, unless one of them alone places every marker of
  its cluster, or that a twin fits better (two hands alike: :mod:`.rival_clusters`).
  Markers still
  missing after the segment fits (a marker on no rigid cluster, or a segment with fewer
  than three markers in view) are labelled by the distance ranges to their labelled
  partners (:class:`.model.Link`, segment mates), only where the point and the marker
  fit each other and nothing else, and two segment mates labelled so together keep
  their segment distance (:mod:`.link_labels`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import linear_sum_assignment

from spotlab.core.errors import ReconstructionError
from spotlab.reconstruction._rigid_identity import choose_identity
from spotlab.reconstruction.identification.candidate_sides import turned_over
from spotlab.reconstruction.identification.handedness import Reference, wrong_way_round
from spotlab.reconstruction.identification.identity_trial import LinkRounds, Trial, trial_of
from spotlab.reconstruction.identification.link_labels import exchanged_labels, linked_labels
from spotlab.reconstruction.identification.link_ranges import length
from spotlab.reconstruction.identification.model import MarkerModel, Segment
from spotlab.reconstruction.identification.rival_clusters import Offer, rivals, twin_leads
from spotlab.reconstruction.rigid import rigid_fit

__all__ = ["assign_labels", "inconsistent_labels"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]


def inconsistent_labels(
    model: MarkerModel, points: FloatArray, age: IntArray, tol_mm: float
) -> NDArray[np.bool_]:
    """Labelled points that do not fit their segment or their links.

    Parameters
    ----------
    model : MarkerModel
    points : ndarray, shape (M, 3)
        Labelled points of one frame (mm), NaN where missing.
    age : ndarray of int, shape (M,)
        Frames each label has been held (kept for callers that rank labels; two markers
        whose only distance disagrees both lose their labels).
    tol_mm : float
        Largest accepted error of a model distance (or distance outside a link's range).

    Returns
    -------
    ndarray of bool, shape (M,)
        True for labels to drop.
    """
    i, j, lo, hi = model.intervals
    dist = length(points[i] - points[j])
    err = np.maximum(np.maximum(lo - dist, dist - hi), 0.0)  # NaN where one is missing
    both = np.isfinite(err)
    bad = both & (err > tol_mm)
    M = points.shape[0]
    # counts as float sums of 0 / 1 weights: exact, and no masked copies of i and j
    checked = np.bincount(i, both, M) + np.bincount(j, both, M)
    wrong = np.bincount(i, bad, M) + np.bincount(j, bad, M)
    drop = (checked >= 2) & (2 * wrong > checked)
    lone = np.flatnonzero(bad & ((checked[i] == 1) | (checked[j] == 1)))
    drop[i[lone]] = True  # one distance cannot say which of the two is wrong
    drop[j[lone]] = True
    return np.asarray(drop)


def _tree(
    seg: Segment, points: FloatArray, fixed: IntArray, free: IntArray, tol_mm: float
) -> NDArray[np.intp]:
    """Assignments (n, P) of points to the segment's markers that keep model distances.

    ``fixed[p]`` is the point already labelled as marker ``p`` (or -1); a marker without
    one may take any of ``free`` that keeps the distances, or stay missing (-1). Once a
    row has two points, a marker stays missing only where no point fits it: the tree
    keeps the largest assignments, not every subset of them (2^P rows for P markers).
    """
    model = seg.coordinates
    # Work on the few points the tree can use (local indices), their distances once.
    have = np.flatnonzero(fixed >= 0)
    local = np.concatenate([fixed[have], free]).astype(np.intp)
    fixed_local = np.full(fixed.size, -1, dtype=np.intp)
    fixed_local[have] = np.arange(have.size)
    free_local = np.arange(have.size, local.size)
    X = points[local]
    dist = length(X[:, None] - X[None])
    other = ~np.eye(local.size, dtype=bool)  # a point is one marker at most
    rows = np.zeros((1, 0), dtype=np.intp)
    for p in range(model.shape[0]):
        if fixed[p] >= 0:
            options = np.array([fixed_local[p]])
        else:
            options = np.concatenate([free_local, [-1]])
        n = rows.shape[0]
        parent = np.repeat(np.arange(n), options.size)
        rows = np.hstack([rows[parent], np.tile(options, n)[:, None]])
        new = rows[:, p]
        ok = np.ones(rows.shape[0], dtype=bool)
        for q in range(p):
            old = rows[:, q]
            both = (old >= 0) & (new >= 0)
            d_model = float(np.linalg.norm(model[p] - model[q]))
            fits = (np.abs(dist - d_model) <= tol_mm) & other
            ok &= ~both | fits[np.maximum(old, 0), np.maximum(new, 0)]
        placed = (rows[:, :p] >= 0).sum(axis=1) >= 2
        fitted = np.bincount(parent[ok & (new >= 0)], minlength=n) > 0
        ok &= ~((new < 0) & placed & fitted[parent])
        rows = rows[ok]
    return np.where(rows >= 0, local[np.maximum(rows, 0)], -1)


def _predicted(seg: Segment, points: FloatArray, fixed: IntArray) -> FloatArray | None:
    """Positions (P, 3) of the segment's markers from its labelled points, or None."""
    have = fixed >= 0
    if have.sum() < 3:
        return None
    observed = np.full((1, len(seg.markers), 3), np.nan)
    observed[0, have] = points[fixed[have]]
    R, t, _ = rigid_fit(seg.coordinates, observed)
    if not np.isfinite(R).all():
        return None
    return np.asarray(seg.coordinates @ R[0].T + t[0])


def assign_labels(
    model: MarkerModel,
    points: FloatArray,
    labels: IntArray,
    *,
    tol_mm: float,
    rms_mm: float,
    margin_mm: float,
    near_mm: float = 600.0,
    anchors: FloatArray | None = None,
    min_links: int = 3,
    linkable: NDArray[np.bool_] | None = None,
    twins: dict[int, tuple[int, ...]] | None = None,
) -> IntArray:
    """Labels for the unlabelled points of one frame.

    Parameters
    ----------
    model : MarkerModel
    points : ndarray, shape (K, 3)
        Points of the frame (mm).
    labels : ndarray of int, shape (K,)
        Label of each point (index into ``model.labels``) or -1; labels are unique.
    tol_mm : float
        Distance tolerance of the interpretation tree and of predicted positions.
    rms_mm : float
        Largest RMS fit of an accepted identity.
    margin_mm : float
        Smallest RMS lead over the runner-up of an accepted identity.
    near_mm : float
        Only points within this distance of a segment's anchor are tried for it.
    anchors : ndarray, shape (S, 3), optional
        Last known centre of each segment (NaN where unknown: every point is tried).
    min_links : int
        Labelled partners (links or segment mates) a marker needs to be labelled by
        distance ranges alone, after the segment fits.
    linkable : ndarray of bool, shape (K,), optional
        Points that may take a label by distance ranges alone (default: all); the
        others still count as candidates (two leave a marker unlabelled).
    twins : dict, optional
        Twins of each segment that has any (:func:`.twin_clusters.twin_partners`): a
        new identity a twin fits better, the twin's anchor aside, waits
        (:func:`.rival_clusters.twin_leads`).

    Returns
    -------
    ndarray of int, shape (K,)
        ``labels`` with new labels filled in.

    Raises
    ------
    ReconstructionError
        For arrays of mismatched shapes.
    """
    K = points.shape[0]
    if labels.shape != (K,):
        raise ReconstructionError(f"labels must have shape ({K},)")
    out = labels.copy()
    point_of = np.full(len(model.labels), -1, dtype=np.intp)
    point_of[out[out >= 0]] = np.flatnonzero(out >= 0)
    can = np.ones(K, dtype=bool) if linkable is None else linkable

    def link_rounds(lab: IntArray, where: IntArray) -> None:
        for _ in range(3):  # labels found by links constrain the next markers
            if not linked_labels(model, points, lab, where, tol_mm, min_links, can):
                break

    def anywhere(t: int) -> Offer | None:  # segment t's best identity, its anchor aside
        args = (tol_mm, margin_mm, near_mm, None, link_rounds)
        return _segment_labels(model, t, points, out, point_of, *args)[0]

    pending = list(range(len(model.segments)))
    # A segment's best assignment depends only on its own markers' points and on the
    # free points near it: it is kept until another segment takes one of those.
    known: dict[int, tuple[tuple[float, IntArray] | None, IntArray]] = {}
    while pending:
        offers: dict[int, Offer] = {}
        for s in pending:
            if s not in known:
                known[s] = _segment_labels(
                    model,
                    s,
                    points,
                    out,
                    point_of,
                    tol_mm,
                    margin_mm,
                    near_mm,
                    anchors,
                    link_rounds,
                )
            found = known[s][0]
            if found is not None and found[0] <= rms_mm:
                offers[s] = found
        if not offers:
            break
        s = min(offers, key=lambda t: offers[t][0])  # the first of equal ones
        others = rivals(s, offers, out, margin_mm)
        if others:
            # Woltring's caveat across clusters: two clusters whose best identities take
            # the same new points and fit about as well (two hands alike) both wait,
            # unless one alone places all its markers (the others leave one missing).
            whole = [t for t in (s, *others) if (offers[t][1] >= 0).all()]
            if len(whole) != 1:
                for t in (s, *others):
                    pending.remove(t)
                continue
            s = whole[0]
        rows = offers[s][1]
        if twins and s in twins and not (point_of[list(model.segments[s].markers)] >= 0).any():
            waiting = [t for t in twins[s] if t in pending]
            if twin_leads(offers[s], out, margin_mm, waiting, anywhere):
                pending.remove(s)  # the anchors kept its twin off points it fits better
                continue
        seg = model.segments[s]
        taken = []
        for p, k in enumerate(rows):
            if k >= 0 and out[k] < 0:
                out[k] = seg.markers[p]
                point_of[seg.markers[p]] = k
                taken.append(k)
        pending.remove(s)
        for other in pending:
            if other in known and np.isin(known[other][1], taken).any():
                del known[other]
    link_rounds(out, point_of)
    if exchanged_labels(model, points, out, point_of, tol_mm, min_links, can):
        linked_labels(model, points, out, point_of, tol_mm, min_links, can)
    return out


def _segment_labels(
    model: MarkerModel,
    s: int,
    points: FloatArray,
    labels: IntArray,
    point_of: IntArray,
    tol_mm: float,
    margin_mm: float,
    near_mm: float,
    anchors: FloatArray | None,
    link_rounds: LinkRounds | None = None,
) -> tuple[tuple[float, IntArray] | None, IntArray]:
    """The best new assignment ``(rms, points per marker)`` of segment ``s``, or None;
    with the free points it was chosen among (none when all its markers have points).
    ``link_rounds``: for the trial of a flat cluster's identities (:mod:`.identity_trial`)."""
    seg = model.segments[s]
    fixed = point_of[list(seg.markers)]
    free = np.zeros(0, dtype=np.intp)
    if (fixed >= 0).all():
        return None, free
    free = np.flatnonzero(labels < 0)
    if anchors is not None and np.isfinite(anchors[s]).all():
        free = free[np.linalg.norm(points[free] - anchors[s], axis=1) < near_mm]
    refs = model.references_by_segment.get(s, [])
    ref_rows = point_of[[r.marker for r in refs]] if refs else np.zeros(0, dtype=np.intp)
    trial = trial_of(model, s, points, labels, point_of, link_rounds)
    choice = _segment_choice(seg, points, fixed, free, tol_mm, margin_mm, refs, ref_rows, trial)
    return choice, free


def _segment_choice(
    seg: Segment,
    points: FloatArray,
    fixed: IntArray,
    free: IntArray,
    tol_mm: float,
    margin_mm: float,
    refs: list[Reference] | None = None,
    ref_rows: IntArray | None = None,
    trial: Trial | None = None,
) -> tuple[float, IntArray] | None:
    """:func:`_segment_labels` among the points ``free``, with ``fixed`` (point per marker
    or -1); candidate identities the segment's references ``refs`` (their points
    ``ref_rows``, -1 where unlabelled) refuse are left out (:func:`.wrong_way_round`).
    With none of them labelled, ``trial`` leaves out the candidates the references the
    links then label refuse (:func:`.identity_trial.unrefused`)."""
    if free.size == 0:
        return None
    predicted = _predicted(seg, points, fixed)
    if predicted is not None:
        missing = np.flatnonzero(fixed < 0)
        cost = np.linalg.norm(predicted[missing, None] - points[free][None], axis=2)
        r, c = linear_sum_assignment(np.where(cost < tol_mm, cost, 1e6))
        keep = cost[r, c] < tol_mm
        if not keep.any():
            return None
        rows = fixed.copy()
        rows[missing[r[keep]]] = free[c[keep]]
        return float(np.sqrt(np.mean(cost[r[keep], c[keep]] ** 2))), rows
    table = _tree(seg, points, fixed, free, tol_mm)
    count = (table >= 0).sum(axis=1)
    table = table[(count >= 3) & ((table >= 0) & (fixed < 0)).any(axis=1)]
    if table.shape[0] == 0:
        return None
    table = table[(table >= 0).sum(axis=1) == (table >= 0).sum(axis=1).max()]
    if refs and ref_rows is not None:
        if (ref_rows >= 0).any():
            markers = np.asarray(seg.markers, dtype=np.intp)
            table = table[
                ~wrong_way_round(seg.coordinates, refs, points, table, ref_rows)
                & ~turned_over(markers, refs, points, table, ref_rows)
            ]
            if table.shape[0] == 0:
                return None
        else:
            # A flat cluster none of whose references is labelled yet: its mirror image
            # fits it almost as well, so only a clear lead is taken (a wrong identity
            # taken now would be reported until the references show it), among the
            # identities the references the links would label do not refuse.
            table = table if trial is None else trial(table)
            if table.shape[0] == 0:
                return None
            margin_mm = max(margin_mm, tol_mm)
    choice = choose_identity(seg.coordinates, points, candidates=table.tolist())
    # Woltring's caveat: the smallest RMS is a criterion, not a proof; ambiguous ones wait.
    if choice.margin < margin_mm:
        return None
    return choice.rms, np.array(choice.assignment, dtype=np.intp)
