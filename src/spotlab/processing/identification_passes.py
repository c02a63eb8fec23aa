"""Identifying a whole recording twice, forward and backward in time, and joining the two.

Live, the identifier only knows the frames it has seen: a marker hidden or moving
fast when labelling starts is labelled only once its cluster has been recognised,
and every frame before that stays empty. Offline the whole recording is there, so
:func:`identify_both_ways` runs a second, independent identifier from the last frame
to the first (tracking predicts as well backward as forward) and fills each marker-frame
the forward pass left empty with the backward pass's label. Where both passes label a
marker they must agree (within :data:`AGREE_MM`); where they do not, now and then, that
frame's label is dropped: a gap, never a guess; a filled label that lands on a point
another marker holds is dropped too. A marker on which the passes disagree throughout
(:data:`SYSTEMATIC_SHARE`) keeps the forward labels alone. Before that, each pass loses
the runs of labels the other refutes (:func:`~spotlab.processing.pass_runs.refuted_labels`:
a run the other pass contradicts, where a run it confirms bears it out). Measured on the
simulated walk of a subject the model never saw (docs/identification.md): a walk's first half
second, when a foot or a wrist is still unlabelled, is what the backward pass fills.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from spotlab.core.errors import CalibrationError
from spotlab.geometry import Rig
from spotlab.processing.errors import InputError
from spotlab.processing.pass_runs import JUMP_MM, jump_mm, refuted_labels
from spotlab.processing.progress import ProgressSink
from spotlab.processing.track_bridges import TrackLog, bridge_labels
from spotlab.reconstruction.identification import (
    FLOODED,
    NO_BLOBS,
    BlobFrame,
    Identifier,
    MarkerModel,
)

FloatArray = NDArray[np.float64]

#: Two passes agree on a marker when they put it this close (mm): the same blobs
#: triangulate to the same point; a wrong label is a marker's spacing away.
AGREE_MM = 3.0
#: A marker whose two passes disagree on more than this share of the frames both label
#: it follows another identity in one of them throughout (a mirror-image cluster, two
#: link-only markers exchanged): which one cannot be told from the passes alone, so that
#: marker keeps the forward pass's labels, unfilled and undropped.
SYSTEMATIC_SHARE = 0.1
#: Frames lost in a row beyond which the identifier starts afresh (its prediction
#: takes frames as consecutive; a label is earned again, never carried over a guess).
MAX_LOST_FRAMES = 1


@dataclass
class PassResult:
    """One identification pass over the decoded frames (in recording order).

    Attributes
    ----------
    points : ndarray, shape (F, M, 3)
        Labelled positions (mm) per decoded frame, NaN where not labelled or not
        identified (a frame with no usable blob).
    residual_px : ndarray, shape (F, M)
        Ray residuals (px) of the labelled points.
    ghosts, unlabelled, restarts : int
        Reflection points rejected, points left unlabelled, fresh starts after gaps.
    flooded, no_blobs : ndarray, shape (C,)
        Frames each camera was flagged too full of blobs, or without blobs.
    tracks : TrackLog or None
        The pass's trajectories (:mod:`.track_bridges`); None: not recorded, and
        :func:`join_passes` bridges no gap along them.
    """

    points: FloatArray
    residual_px: FloatArray
    ghosts: int = 0
    unlabelled: int = 0
    restarts: int = 0
    flooded: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64))
    no_blobs: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64))
    tracks: TrackLog | None = None


def identify_pass(
    rig: Rig,
    model: MarkerModel,
    frames: Sequence[tuple[BlobFrame, NDArray[np.bool_]]],
    usable: NDArray[np.bool_],
    frame_no: NDArray[np.int64],
    order: Sequence[int],
    progress: ProgressSink | None = None,
) -> PassResult:
    """Identify ``frames`` in the given ``order`` with one fresh identifier.

    Parameters
    ----------
    rig : Rig
    model : MarkerModel
    frames : sequence of (BlobFrame, unusable cameras (C,) bool)
        The decoded frames in recording order.
    usable : ndarray, shape (F,)
        Frames with at least one usable blob (others are gaps, like lost frames).
    frame_no : ndarray, shape (F,)
        Each frame's number on the hub's frame grid (gaps are lost frames).
    order : sequence of int
        Indices into ``frames`` in the order to identify them (forward or backward).
    progress : ProgressSink, optional
        Told every 256 frames.

    Raises
    ------
    InputError
        When the identification finds that the calibration does not match the cameras.
    """
    F, M, C = len(frames), len(model.labels), len(rig)
    out = PassResult(
        np.full((F, M, 3), np.nan),
        np.full((F, M), np.nan),
        flooded=np.zeros(C, np.int64),
        no_blobs=np.zeros(C, np.int64),
        tracks=TrackLog.empty(F, M),
    )
    identify = Identifier(rig, model)
    offset = 0  # trajectory numbers of earlier identifiers (restarts)
    last: int | None = None
    for k, f in enumerate(order):
        if not usable[f]:
            continue
        if last is not None and abs(int(frame_no[f]) - last) - 1 > MAX_LOST_FRAMES:
            offset += identify.tracks.next_ident
            identify = Identifier(rig, model)
            out.restarts += 1
        last = int(frame_no[f])
        try:
            result = identify(*frames[f])
        except CalibrationError as exc:
            raise InputError(f"frame {int(frame_no[f])}: {exc}") from None
        out.points[f] = result.points
        out.residual_px[f] = result.residual_px
        out.ghosts += result.ghosts
        out.unlabelled += result.unlabelled
        out.flooded += (result.camera_flags & FLOODED) != 0
        out.no_blobs += (result.camera_flags & NO_BLOBS) != 0
        if out.tracks is not None:
            out.tracks.add(f, result, offset)
        if progress is not None and k % 256 == 0:
            progress.update(k, f"{k} of {len(order)} frames")
    return out


def join_passes(
    forward: PassResult, backward: PassResult, jump: float = JUMP_MM
) -> tuple[PassResult, dict[str, int]]:
    """The forward pass, its empty marker-frames filled from the backward pass.

    First each pass loses the labels the other refutes
    (:func:`~spotlab.processing.pass_runs.refuted_labels`, runs cut at ``jump`` mm: see
    :func:`~spotlab.processing.pass_runs.jump_mm`); the rest is joined frame by frame.

    Returns
    -------
    joined : PassResult
        Points and residuals joined; the counters are the forward pass's.
    counts : dict
        ``filled_backward`` (marker-frames the backward pass added) and
        ``label_conflicts`` (marker-frames dropped: the passes disagreed now and then, or
        a label filled from the backward pass fell within :data:`AGREE_MM` of another
        label of the frame) and ``systematic_markers`` (markers whose passes disagreed on
        more than :data:`SYSTEMATIC_SHARE` of their frames: forward labels kept) and
        ``bridged`` (marker-frames filled along a pass's trajectories,
        :func:`~spotlab.processing.track_bridges.bridge_labels`, where neither pass
        labelled them).
    """
    refuted_f = refuted_labels(forward.points, backward.points, AGREE_MM, jump)
    refuted_b = refuted_labels(backward.points, forward.points, AGREE_MM, jump)
    fwd = np.where(refuted_f[..., None], np.nan, forward.points)
    bwd = np.where(refuted_b[..., None], np.nan, backward.points)
    has_f = np.isfinite(fwd[..., 0])
    has_b = np.isfinite(bwd[..., 0])
    both = has_f & has_b
    disagree = both & (np.linalg.norm(fwd - bwd, axis=-1) > AGREE_MM)
    systematic = disagree.sum(axis=0) > SYSTEMATIC_SHARE * np.maximum(both.sum(axis=0), 1)
    disagree &= ~systematic[None, :]
    fill = has_b & ~has_f & ~systematic[None, :]
    points = np.where(fill[..., None], bwd, fwd)
    residual = np.where(fill, backward.residual_px, forward.residual_px)
    drop = disagree | (_doubled(points) & fill)
    points[drop] = np.nan
    closed = drop | refuted_f | refuted_b | systematic[None, :]
    bridged = np.zeros(closed.shape, dtype=bool)
    for one in (forward, backward):
        if one.tracks is not None:
            bridged |= bridge_labels(points, residual, one.points, one.tracks, closed, AGREE_MM)
    doubled = _doubled(points) & bridged
    points[doubled] = np.nan
    bridged &= ~doubled
    residual[~np.isfinite(points[..., 0])] = np.nan
    joined = PassResult(
        points,
        residual,
        forward.ghosts,
        forward.unlabelled,
        forward.restarts,
        forward.flooded,
        forward.no_blobs,
    )
    counts = {
        "filled_backward": int((fill & ~drop).sum()),
        "label_conflicts": int(drop.sum()),
        "systematic_markers": int(systematic.sum()),
        "bridged": int(bridged.sum()),
    }
    return joined, counts


def _doubled(points: FloatArray, chunk: int = 512) -> NDArray[np.bool_]:
    """Marker-frames whose point lies within AGREE_MM of another marker's in the frame."""
    F, M, _ = points.shape
    out = np.zeros((F, M), dtype=bool)
    eye = np.eye(M, dtype=bool)
    for a in range(0, F, chunk):
        p = points[a : a + chunk]
        with np.errstate(invalid="ignore"):
            d = np.linalg.norm(p[:, :, None, :] - p[:, None, :, :], axis=-1)
            close = (d < AGREE_MM) & ~eye
        out[a : a + chunk] = close.any(axis=2)
    return out


def identify_both_ways(
    rig: Rig,
    model: MarkerModel,
    frames: Sequence[tuple[BlobFrame, NDArray[np.bool_]]],
    usable: NDArray[np.bool_],
    frame_no: NDArray[np.int64],
    progress: ProgressSink | None = None,
) -> tuple[PassResult, dict[str, Any]]:
    """Identify forward, then backward, and join (:func:`join_passes`).

    Returns
    -------
    joined : PassResult
    counts : dict
        As :func:`join_passes` gives them.
    """
    F = len(frames)
    forward = identify_pass(rig, model, frames, usable, frame_no, range(F), progress)
    backward = identify_pass(rig, model, frames, usable, frame_no, range(F - 1, -1, -1))
    return join_passes(forward, backward, jump_mm(model))
