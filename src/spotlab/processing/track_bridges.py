"""Labels along unbroken trajectories: an offline pass's gaps bridged by its own tracks.

Live, a label lost by the model's checks (a skin marker whose distances leave the ranges
the model learnt, in a posture the learning trial never reached) stays lost until the
marker's cluster or links give it again; the track under it goes on, unlabelled.
Offline, the unit to label is the trajectory (the path of one marker; Qualisys's QTM
labels trajectories so, docs/identification.md gives the source), not the frame: a
trajectory keeps one label along its length. :func:`bridge_labels` does that for a pass: a
trajectory (:attr:`~spotlab.reconstruction.identification.tracking.Tracks.ident`: one
number for as long as the identifier has no reason to doubt the track stays on one
marker) that the joined labels put on marker ``m``, and on no other marker, anywhere
along it, is ``m`` in its unlabelled frames between the first and the last of those.
A track that passed to another marker and was labelled there too is left alone; one
labelled at one end only is not extended (a label is never carried past its last
confirmation). Measured in docs/identification.md.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from spotlab.reconstruction.identification import IdentifiedFrame

__all__ = ["TrackLog", "bridge_labels"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]

#: Rows compared with the labels at once (memory: rows x markers distances).
CHUNK = 8192


@dataclass
class TrackLog:
    """Where one pass's trajectories were, frame by frame.

    Attributes
    ----------
    trajectory : ndarray of int, shape (F, M)
        Trajectory number of each labelled marker-frame, -1 where not labelled.
    frames, numbers : list of ndarray of int
        Per recorded frame: its index and its unlabelled points' trajectory numbers.
    points : list of ndarray, shape (U, 3)
        Per recorded frame: its unlabelled points (mm).
    residuals : list of ndarray, shape (U,)
        Per recorded frame: their RMS ray errors (px).
    """

    trajectory: IntArray
    frames: list[IntArray] = field(default_factory=list)
    numbers: list[IntArray] = field(default_factory=list)
    points: list[FloatArray] = field(default_factory=list)
    residuals: list[FloatArray] = field(default_factory=list)

    @classmethod
    def empty(cls, n_frames: int, n_markers: int) -> TrackLog:
        """A log of ``n_frames`` frames of ``n_markers`` markers, nothing recorded."""
        return cls(np.full((n_frames, n_markers), -1, dtype=np.int64))

    def add(self, f: int, result: IdentifiedFrame, offset: int = 0) -> None:
        """Record frame ``f``'s trajectories from the identifier's ``result``, their
        numbers raised by ``offset`` (an identifier started afresh numbers from 0)."""
        if result.trajectory.size:
            self.trajectory[f] = np.where(result.trajectory >= 0, result.trajectory + offset, -1)
        n = result.loose_trajectory.size
        if n:
            self.frames.append(np.full(n, f, dtype=np.int64))
            self.numbers.append(result.loose_trajectory.astype(np.int64) + offset)
            self.points.append(result.loose_points)
            self.residuals.append(result.loose_residual_px)

    def loose(self) -> tuple[IntArray, IntArray, FloatArray, FloatArray]:
        """Every unlabelled point: frame (N,), trajectory number (N,), position (N, 3)
        mm, RMS ray error (N,) px."""
        if not self.frames:
            return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros(0)
        return (
            np.concatenate(self.frames),
            np.concatenate(self.numbers),
            np.concatenate(self.points),
            np.concatenate(self.residuals),
        )


def bridge_labels(
    joined: FloatArray,
    residual: FloatArray,
    own: FloatArray,
    log: TrackLog,
    closed: BoolArray,
    agree_mm: float,
) -> BoolArray:
    """Marker-frames of ``joined`` to fill along the pass's trajectories.

    Parameters
    ----------
    joined : ndarray, shape (F, M, 3)
        Labelled points (mm) as joined so far, NaN where missing; filled in place.
    residual : ndarray, shape (F, M)
        Their RMS ray errors (px); filled in place with the bridged points'.
    own : ndarray, shape (F, M, 3)
        The pass's own labelled points (mm), as it gave them.
    log : TrackLog
        The pass's trajectories.
    closed : ndarray of bool, shape (F, M)
        Marker-frames not to fill (the passes disagreed there, or a marker whose
        passes disagree throughout).
    agree_mm : float
        A trajectory's point is a marker's when within this distance of its label.

    Returns
    -------
    ndarray of bool, shape (F, M)
        The marker-frames filled.
    """
    F, M = log.trajectory.shape
    fl, ml = np.nonzero(log.trajectory >= 0)
    lf, ln, lp, lr = log.loose()
    frame = np.concatenate([fl, lf])
    number = np.concatenate([log.trajectory[fl, ml], ln])
    point = np.concatenate([own[fl, ml], lp])
    filled = np.zeros((F, M), dtype=bool)
    if frame.size == 0:
        return filled
    marker = _nearest_label(joined, frame, point, agree_mm)
    ids, row_id = np.unique(number, return_inverse=True)
    K = ids.size
    on = marker >= 0
    lo_m = np.full(K, M, dtype=np.int64)
    hi_m = np.full(K, -1, dtype=np.int64)
    first = np.full(K, F, dtype=np.int64)
    last = np.full(K, -1, dtype=np.int64)
    np.minimum.at(lo_m, row_id[on], marker[on])
    np.maximum.at(hi_m, row_id[on], marker[on])
    np.minimum.at(first, row_id[on], frame[on])
    np.maximum.at(last, row_id[on], frame[on])
    one = lo_m == hi_m  # labelled somewhere, as one marker only
    m = lo_m[row_id]
    loose = np.arange(frame.size) >= fl.size  # the pass gave them no label
    take = loose & ~on & one[row_id] & (frame > first[row_id]) & (frame < last[row_id])
    rows = np.flatnonzero(take)
    f, mk = frame[rows], m[rows]
    take_rows = ~closed[f, mk] & ~np.isfinite(joined[f, mk, 0])
    rows, f, mk = rows[take_rows], f[take_rows], mk[take_rows]
    # two trajectories bridging one marker in one frame: neither is taken
    key = f * M + mk
    uniq, count = np.unique(key, return_counts=True)
    single = np.isin(key, uniq[count == 1])
    rows, f, mk = rows[single], f[single], mk[single]
    joined[f, mk] = point[rows]
    residual[f, mk] = np.concatenate([np.full(fl.size, np.nan), lr])[rows]
    filled[f, mk] = True
    return filled


def _nearest_label(
    joined: FloatArray, frame: IntArray, point: FloatArray, agree_mm: float
) -> IntArray:
    """The marker (N,) whose joined label lies within ``agree_mm`` of each point, -1 for
    none (the nearest where several do)."""
    out = np.full(frame.size, -1, dtype=np.int64)
    for a in range(0, frame.size, CHUNK):
        p = point[a : a + CHUNK]
        with np.errstate(invalid="ignore"):
            d = np.linalg.norm(joined[frame[a : a + CHUNK]] - p[:, None, :], axis=-1)
        d = np.where(np.isfinite(d), d, np.inf)
        best = np.argmin(d, axis=1)
        near = d[np.arange(best.size), best] < agree_mm
        out[a : a + CHUNK] = np.where(near, best, -1)
    return out
