"""Marker identities of a rigid body chosen by the smallest RMS fit (Woltring & Huiskes 1990)."""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from spotlab.core.errors import ReconstructionError
from spotlab.reconstruction.rigid import check_body_model, rigid_pose

__all__ = ["IdentityChoice", "choose_identity"]

FloatArray = NDArray[np.float64]

#: Above this many candidate assignments the caller must narrow them down.
MAX_CANDIDATES = 200_000


@dataclass(frozen=True)
class IdentityChoice:
    """The best assignment of unlabelled points to body markers.

    Attributes
    ----------
    assignment : tuple of int, length P
        ``assignment[p]`` is the index of the point taken as model marker ``p``, or
        -1 where the marker is left unassigned (missing).
    rms : float
        RMS fit of that assignment (mm).
    margin : float
        RMS of the runner-up minus ``rms`` (mm); ``inf`` with a single candidate. A
        margin near the noise level means the choice is ambiguous (a symmetric body).
    R : ndarray, shape (3, 3)
        Pose of the best assignment.
    t : ndarray, shape (3,)
        Position of the best assignment (mm).
    candidates : int
        Number of candidates that could be fitted.
    """

    assignment: tuple[int, ...]
    rms: float
    margin: float
    R: FloatArray
    t: FloatArray
    candidates: int


def _all_assignments(n_points: int, n_markers: int) -> list[tuple[int, ...]]:
    k = min(n_points, n_markers)
    count = math.perm(n_markers, k) * math.comb(n_points, k)
    if count > MAX_CANDIDATES:
        raise ReconstructionError(
            f"{count} candidate assignments of {n_points} points to {n_markers} markers: "
            f"more than {MAX_CANDIDATES}; pass the plausible ones as candidates"
        )
    out = []
    for markers in itertools.permutations(range(n_markers), k):
        for pts in itertools.combinations(range(n_points), k):
            a = [-1] * n_markers
            for mk, pt in zip(markers, pts, strict=True):
                a[mk] = pt
            out.append(tuple(a))
    return out


def choose_identity(
    model: Any,
    points: Any,
    candidates: Iterable[Iterable[int]] | None = None,
    weights: Any = None,
) -> IdentityChoice:
    """Assign unlabelled 3-D points to the markers of a body by the smallest RMS fit.

    Parameters
    ----------
    model : array_like, shape (P, 3)
        Marker coordinates in the body frame (mm).
    points : array_like, shape (Q, 3)
        Unlabelled reconstructed points of one frame (mm); Q may differ from P.
    candidates : iterable of sequences of P ints, optional
        The assignments to try: entry ``p`` is the point index for marker ``p`` or -1.
        Default: every one-to-one assignment of ``min(P, Q)`` points to markers.
    weights : array_like, shape (P,), optional
        Marker weights for the fit.

    Returns
    -------
    IdentityChoice
        Best assignment, its RMS, the margin to the runner-up and the pose.

    Raises
    ------
    ReconstructionError
        Fewer than 3 points, a bad candidate (wrong length, index out of range, a
        point used twice), too many candidates, or no candidate that can be fitted.

    Notes
    -----
    Woltring & Huiskes (1990): "if the identity of some data is unknown, one may use
    the rms fitting error to decide between candidate solutions"; they add that the
    criterion does not guarantee the right choice, hence the margin. Every candidate
    is one "frame" of a single vectorised :func:`rigid_pose` call.
    """
    m = check_body_model(model)
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ReconstructionError(f"points must have shape (Q, 3), got {pts.shape}")
    if pts.shape[0] < 3:
        raise ReconstructionError(f"{pts.shape[0]} points: identification needs at least 3")
    P, Q = m.shape[0], pts.shape[0]
    cands = _all_assignments(Q, P) if candidates is None else [tuple(c) for c in candidates]
    if not cands:
        raise ReconstructionError("no candidate assignment given")
    table = np.array(cands, dtype=np.int64)
    if table.ndim != 2 or table.shape[1] != P:
        raise ReconstructionError(f"each candidate must list {P} point indices (or -1)")
    if np.any((table < -1) | (table >= Q)):
        raise ReconstructionError(f"candidate point indices must be -1 or in 0..{Q - 1}")
    for row in table:
        used = row[row >= 0]
        if used.size != np.unique(used).size:
            raise ReconstructionError(f"candidate {tuple(row)} uses a point twice")
    padded = np.vstack([pts, np.full((1, 3), np.nan)])
    observed = padded[np.where(table >= 0, table, Q)]
    pose = rigid_pose(m, observed, weights)
    if not np.any(pose.valid):
        raise ReconstructionError(
            "no candidate assignment has 3 non-collinear markers that can be fitted"
        )
    rms = np.where(pose.valid, pose.rms, np.inf)
    order = np.argsort(rms, kind="stable")
    best = int(order[0])
    margin = float(rms[order[1]] - rms[best]) if len(order) > 1 else math.inf
    return IdentityChoice(
        assignment=tuple(int(i) for i in table[best]),
        rms=float(rms[best]),
        margin=margin,
        R=pose.R[best],
        t=pose.t[best],
        candidates=int(np.count_nonzero(pose.valid)),
    )
