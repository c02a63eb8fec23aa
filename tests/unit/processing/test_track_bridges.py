"""Labels along unbroken trajectories: a pass's gaps filled where its own track holds one
marker's label before and after, and nowhere else; on a real jump, what carries the
labels through a posture the model never saw."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from spotlab.io import labelled_markers, read_trial
from spotlab.processing.identification_passes import (
    AGREE_MM,
    PassResult,
    identify_pass,
    join_passes,
)
from spotlab.processing.pass_runs import jump_mm
from spotlab.processing.track_bridges import TrackLog, bridge_labels
from spotlab.reconstruction.identification import IdentifiedFrame, MarkerModel
from spotlab.testing.trial_scene import trial_scene

DATA = Path(__file__).resolve().parents[3].parent / "shared" / "data"

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


def _pass(labelled: dict[int, list[int]], after: int | None = None) -> PassResult:
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


def _log(one: PassResult) -> TrackLog:
    assert one.tracks is not None
    return one.tracks


def test_a_gap_on_one_trajectory_is_filled_between_its_labels() -> None:
    one = _pass({0: [0, 1, 2, 3, 9, 10, 11]})
    joined = one.points.copy()
    residual = one.residual_px.copy()
    closed = np.zeros((F, M), dtype=bool)
    closed[5, 0] = True
    filled = bridge_labels(joined, residual, one.points, _log(one), closed, AGREE_MM)
    assert np.flatnonzero(filled[:, 0]).tolist() == [4, 6, 7, 8]
    assert not filled[:, 1:].any()
    assert np.allclose(joined[[4, 6, 7, 8], 0], _truth()[[4, 6, 7, 8], 0])
    assert np.isnan(joined[5, 0]).all() and residual[4, 0] == 0.2


def test_no_fill_past_the_last_label_or_across_two_markers() -> None:
    tail = _pass({0: [0, 1, 2]})  # never labelled again: not carried on
    joined = tail.points.copy()
    none = np.zeros((F, M), dtype=bool)
    assert not bridge_labels(
        joined, tail.residual_px.copy(), tail.points, _log(tail), none, AGREE_MM
    ).any()
    swapped = _pass({0: [0, 1, 2]}, after=8)  # labelled 0, then 1: whose it is is unknown
    joined = swapped.points.copy()
    assert not bridge_labels(
        joined, swapped.residual_px.copy(), swapped.points, _log(swapped), none, AGREE_MM
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


#: The markers of Motion Analysis's Sample_Jump2.c3d that cameras saw: the file's
#: labelled points less those a program computed from them, as
#: benchmarks/identification_real.py finds them (its "left_out" line).
JUMP_MARKERS = (
    "THEA FHEA RHEA RSHO ROFF RELB RWRI LSHO LELB LWRI RASI LASI VSAC RTHI RKNE RKNE#2 "
    "RSHA RANK R.TO LTHI LKNE LKNE#2 LSHA LANK LANK#2 LHEE VRAN#2 VLAN#2"
).split()


def test_a_landing_crouch_the_model_never_saw_keeps_its_labels() -> None:
    """Sample_Jump2.c3d (120 Hz), model learnt from its first half (quiet stance), the
    second half (the jump) labelled both ways in the simulated rig, seed 2: the crouch
    takes link-only markers out of their learnt ranges, and only the trajectories they
    stay on carry them through (benchmarks/identification_real.py, the same figures)."""
    path = DATA / "c3d_org_samples" / "sample00" / "Motion Analysis Corporation"
    path = path / "Sample_Jump2.c3d"
    assert path.is_file(), f"reference data missing: {path}"
    trial = read_trial(path)
    labels, X = labelled_markers(trial, path)
    X = X[:, [labels.index(name) for name in JUMP_MARKERS]]
    seen = np.flatnonzero(np.isfinite(X).all(axis=2).mean(axis=1) >= 0.8)
    X = X[seen[0] : seen[-1] + 1]
    h = round(X.shape[0] / 2)
    model = MarkerModel.infer(JUMP_MARKERS, X[:h])
    scene = trial_scene(X, JUMP_MARKERS, trial.point_rate, seed=2)
    none = np.zeros(len(scene.rig), dtype=bool)  # no camera flagged unusable
    frames = [(scene.frames[f], none) for f in range(h, len(scene))]
    n = len(frames)
    usable, numbers = np.ones(n, dtype=bool), np.arange(n)
    forward = identify_pass(scene.rig, model, frames, usable, numbers, range(n))
    backward = identify_pass(scene.rig, model, frames, usable, numbers, range(n - 1, -1, -1))
    joined, counts = join_passes(forward, backward, jump_mm(model))
    plain, _ = join_passes(
        PassResult(forward.points, forward.residual_px),
        PassResult(backward.points, backward.residual_px),
        jump_mm(model),
    )
    truth = scene.markers_mm[h:]
    visible = np.isfinite(truth[..., 0]) & (scene.own_blobs[h:] >= 2)
    for points, least, most in ((joined.points, 0.97, 1.0), (plain.points, 0.0, 0.94)):
        err = np.linalg.norm(points - truth, axis=-1)
        reported = np.isfinite(err)
        assert (reported & (err >= 10.0)).sum() == 0  # no wrong label either way
        # measured: 0.9721 along trajectories (122 bridged), 0.9374 without
        assert least <= (reported & (err < 10.0))[visible].mean() <= most
    assert counts["bridged"] > 100
