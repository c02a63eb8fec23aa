"""Labels along unbroken trajectories: a pass's gaps filled where its own track holds one
marker's label before and after, and nowhere else."""

from __future__ import annotations

import numpy as np

from spotlab.processing.identification_passes import AGREE_MM, PassResult, join_passes
from spotlab.processing.track_bridges import TrackLog, bridge_labels
from spotlab.reconstruction.identification import IdentifiedFrame

F, M = 12, 3


def _truth() -> np.ndarray:
    f = np.arange(F, dtype=float)[:, None, None]
    return np.array([[0.0, 0.0, 0.0], [200.0, 0.0, 0.0], [0.0, 300.0, 0.0]]) + f * [5.0, 0, 0]


def _frame(
    points: np.ndarray, trajectory: np.ndarray, loose: dict[int, np.ndarray]
) -> IdentifiedFrame:
    return IdentifiedFrame(
        points=points,
        residual_px=np.where(np.isfinite(points[:, 0]), 0.1, np.nan),
        n_cameras=np.zeros(M, dtype=np.intp),
        unlabelled=len(loose),
        ghosts=0,
        camera_flags=np.zeros(2, dtype=np.intp),
        trajectory=trajectory,
        loose_points=np.array(list(loose.values())).reshape(-1, 3),
        loose_trajectory=np.array(list(loose), dtype=np.intp),
        loose_residual_px=np.full(len(loose), 0.2),
    )


def _pass(labelled: dict[int, range], after: int | None = None) -> PassResult:
    """Marker 0 on trajectory 7 throughout, labelled in the frames ``labelled[0]``,
    unlabelled (a loose point of trajectory 7) elsewhere; with ``after``, trajectory 7
    is labelled as marker 1 from that frame on (it passed to marker 1's blobs)."""
    X = _truth()
    log = TrackLog.empty(F, M)
    points = np.full((F, M, 3), np.nan)
    for f in range(F):
        traj = np.full(M, -1, dtype=np.intp)
        loose: dict[int, np.ndarray] = {}
        points[f, 1:] = X[f, 1:]
        traj[1:] = [8, 9]
        if after is not None and f >= after:
            points[f, 1], traj[1] = X[f, 0], 7
            points[f, 0] = np.nan
        elif f in labelled[0]:
            points[f, 0], traj[0] = X[f, 0], 7
        else:
            loose[7] = X[f, 0]
        log.add(f, _frame(points[f], traj, loose))
    return PassResult(points, np.where(np.isfinite(points[..., 0]), 0.1, np.nan), tracks=log)


def test_a_gap_on_one_trajectory_is_filled_between_its_labels() -> None:
    one = _pass({0: [0, 1, 2, 3, 9, 10, 11]})
    joined = one.points.copy()
    residual = one.residual_px.copy()
    closed = np.zeros((F, M), dtype=bool)
    closed[5, 0] = True
    filled = bridge_labels(joined, residual, one.points, one.tracks, closed, AGREE_MM)
    assert np.flatnonzero(filled[:, 0]).tolist() == [4, 6, 7, 8]
    assert not filled[:, 1:].any()
    assert np.allclose(joined[[4, 6, 7, 8], 0], _truth()[[4, 6, 7, 8], 0])
    assert np.isnan(joined[5, 0]).all() and residual[4, 0] == 0.2


def test_no_fill_past_the_last_label_or_across_two_markers() -> None:
    tail = _pass({0: [0, 1, 2]})  # never labelled again: not carried on
    joined = tail.points.copy()
    none = np.zeros((F, M), dtype=bool)
    assert not bridge_labels(
        joined, tail.residual_px.copy(), tail.points, tail.tracks, none, AGREE_MM
    ).any()
    swapped = _pass({0: [0, 1, 2]}, after=8)  # labelled 0, then 1: whose it is is unknown
    joined = swapped.points.copy()
    assert not bridge_labels(
        joined, swapped.residual_px.copy(), swapped.points, swapped.tracks, none, AGREE_MM
    ).any()


def test_the_other_pass_label_closes_a_trajectory() -> None:
    """The forward pass loses marker 0 at frame 3 and never labels it again; the
    backward pass labels it only in the last frames: the forward trajectory joins them."""
    forward = _pass({0: [0, 1, 2]})
    backward = _pass({0: [10, 11]})
    joined, counts = join_passes(forward, backward, 20.0)
    assert counts["bridged"] == 7  # frames 3-9
    assert np.allclose(joined.points[:, 0], _truth()[:, 0])
    without = join_passes(
        PassResult(forward.points, forward.residual_px),
        PassResult(backward.points, backward.residual_px),
        20.0,
    )
    assert without[1]["bridged"] == 0 and np.isnan(without[0].points[3:10, 0]).all()
