"""Forward and backward identification joined: the backward pass fills what the forward one
left empty; disagreements and two labels on one point are dropped, never guessed; on a
simulated walk the joined labels keep every forward label."""

from __future__ import annotations

import numpy as np

from spotlab.processing.identification_passes import (
    AGREE_MM,
    PassResult,
    identify_both_ways,
    identify_pass,
    join_passes,
)
from spotlab.reconstruction.identification import MarkerModel
from spotlab.testing.centroid_scene import centroid_scene


def _pass(points: np.ndarray) -> PassResult:
    return PassResult(points, np.where(np.isfinite(points[..., 0]), 0.1, np.nan))


def test_join_fills_agrees_and_drops() -> None:
    F, M = 40, 4
    truth = np.arange(F * M * 3, dtype=float).reshape(F, M, 3) * 100.0
    fwd, bwd = truth.copy(), truth.copy()
    fwd[0, 0] = np.nan  # filled from the backward pass
    bwd[1, 1] = np.nan  # the forward pass's alone
    bwd[2, 2] += [0.0, 0.0, 0.5 * AGREE_MM]  # the same point, within the tolerance
    bwd[3, 0] += [0.0, 2.0 * AGREE_MM, 0.0]  # the passes disagree once: dropped
    fwd[5, 1] = np.nan  # the backward pass would fill marker 1 on marker 2's point
    bwd[5, 1] = truth[5, 2]
    bwd[:, 3] = truth[:, 3] + [50.0, 0.0, 0.0]  # marker 3: another identity throughout
    fwd[7, 3] = np.nan
    joined, counts = join_passes(_pass(fwd), _pass(bwd))
    got = joined.points
    assert np.array_equal(got[0, 0], truth[0, 0]) and np.array_equal(got[1, 1], truth[1, 1])
    assert np.array_equal(got[2, 2], truth[2, 2])  # the forward point is kept
    assert np.isnan(got[3, 0]).all()
    assert np.isnan(got[5, 1]).all() and np.array_equal(got[5, 2], truth[5, 2])
    # the systematic marker keeps the forward labels, unfilled
    assert np.isnan(got[7, 3]).all()
    kept = np.arange(F) != 7
    assert np.array_equal(got[kept, 3], truth[kept, 3])
    assert counts == {
        "filled_backward": 1,
        "label_conflicts": 2,
        "systematic_markers": 1,
        "bridged": 0,
    }
    assert np.isnan(joined.residual_px[3, 0]) and joined.residual_px[0, 0] == 0.1


def test_both_ways_on_a_walk_keeps_what_the_forward_pass_labelled() -> None:
    """The last 1.2 s of a simulated walk labelled cold, with a model learnt from the
    walk's first 3 s (frames the labelling never sees). What the backward pass gains on
    a new subject, whose model is learnt from another trial, is measured by
    benchmarks/new_subject.py and the end-to-end test."""
    walk = centroid_scene(4.2, 100.0, seed=5)
    model = MarkerModel.infer(list(walk.labels), walk.markers_mm[:300])
    first = 300
    frames = [(walk.frame(f), walk.unusable(f)) for f in range(first, len(walk))]
    usable = np.ones(len(frames), dtype=bool)
    numbers = np.arange(len(frames))
    forward = identify_pass(walk.rig, model, frames, usable, numbers, range(len(frames)))
    joined, counts = identify_both_ways(walk.rig, model, frames, usable, numbers)
    truth = walk.markers_mm[first:, [walk.labels.index(x) for x in model.labels]]

    def right(points: np.ndarray) -> tuple[float, int]:
        reported = np.isfinite(points[..., 0])
        near = np.linalg.norm(points - truth, axis=-1) < 10.0
        return float((reported & near).mean()), int((reported & ~near).sum())

    (fwd_right, fwd_wrong), (both_right, both_wrong) = right(forward.points), right(joined.points)
    print(f"forward {fwd_right:.4f} ({fwd_wrong} wrong), both {both_right:.4f} ({both_wrong})")
    assert both_wrong == 0 and both_right >= fwd_right > 0.99
    kept = np.isfinite(forward.points[..., 0])
    assert np.array_equal(joined.points[kept], forward.points[kept])
    assert counts["label_conflicts"] == 0
