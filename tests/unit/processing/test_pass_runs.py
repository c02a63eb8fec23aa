"""Runs of a pass's labels, and the runs the other pass refutes: a pass that took a
marker wrongly and then rightly loses the wrong run; two passes each following their
own identity throughout refute nothing."""

from __future__ import annotations

import numpy as np

from spotlab.processing.identification_passes import AGREE_MM, PassResult, join_passes
from spotlab.processing.pass_runs import label_runs, refuted_labels

F = 30


def _two_markers() -> np.ndarray:
    """(F, 2, 3) two markers 50 mm apart moving 5 mm a frame along x."""
    t = np.arange(F, dtype=float)[:, None] * [5.0, 0.0, 0.0]
    return np.stack([t, t + np.array([0.0, 50.0, 0.0])], axis=1)


def test_runs_end_at_gaps_and_jumps() -> None:
    truth = _two_markers()
    points = truth.copy()
    points[:10, 0] = truth[:10, 1]  # marker 0 on marker 1's point, then on its own
    points[20, 0] = np.nan
    runs = label_runs(points, jump=20.0)[:, 0]
    assert len(set(runs[:10])) == 1 and len(set(runs[10:20])) == 1 and runs[20] == -1
    assert len({runs[0], runs[10], runs[21]}) == 3


def test_a_wrong_run_the_other_pass_refutes_is_replaced() -> None:
    truth = _two_markers()
    forward = truth.copy()
    forward[:12, 1] = np.nan  # a late start, marker 0 taken on marker 1's point first
    forward[:12, 0] = np.nan
    forward[12:18, 0] = truth[12:18, 1]
    backward = truth.copy()
    backward[:, 1] = np.nan  # the backward pass silent on marker 1
    refuted = refuted_labels(forward, backward, AGREE_MM, 20.0)
    assert refuted[12:18, 0].all() and refuted.sum() == 6
    assert not refuted_labels(backward, forward, AGREE_MM, 20.0).any()
    ones = np.full((F, 2), 0.1)
    joined, _ = join_passes(PassResult(forward, ones), PassResult(backward, ones), 20.0)
    assert np.array_equal(joined.points[:, 0], truth[:, 0])


def test_passes_on_two_identities_throughout_refute_nothing() -> None:
    truth = _two_markers()
    swapped = truth[:, ::-1].copy()
    forward = truth.copy()
    forward[10:12] = np.nan
    assert not refuted_labels(forward, swapped, AGREE_MM, 20.0).any()
    assert not refuted_labels(swapped, forward, AGREE_MM, 20.0).any()


def test_a_label_on_a_point_the_other_pass_names_otherwise_is_refuted() -> None:
    truth = _two_markers()
    forward = truth.copy()
    forward[:, 0] = np.nan
    forward[12, 0] = truth[12, 1]  # marker 0 once, on marker 1's point
    forward[12, 1] = np.nan
    backward = truth.copy()
    backward[:, 0] = np.nan  # the backward pass silent on marker 0
    refuted = refuted_labels(forward, backward, AGREE_MM, 20.0)
    assert refuted[12, 0] and refuted.sum() == 1


def test_the_other_half_of_an_exchange_is_refuted_with_the_first() -> None:
    # sample28/dynamic.C3D, seed 2, in small: the forward pass exchanges the two markers
    # for a few frames; marker 0's wrong run adjoins its right one and is refuted, and
    # marker 1's wrong run goes with it: the backward pass's marker 0 labels, which
    # only the refuted run stood against, put marker 0 on that point.
    truth = _two_markers()
    forward = np.full_like(truth, np.nan)
    forward[4:20, 0] = truth[4:20, 1]  # marker 0 on marker 1's point, then its own
    forward[20:, 0] = truth[20:, 0]
    forward[5:9, 1] = truth[5:9, 0]  # marker 1 on marker 0's point, then a gap
    forward[22:, 1] = truth[22:, 1]
    backward = np.full_like(truth, np.nan)
    backward[:24, 1] = truth[:24, 1]
    backward[6:9, 0] = truth[6:9, 0]
    backward[20:, 0] = truth[20:, 0]
    refuted = refuted_labels(forward, backward, AGREE_MM, 20.0)
    assert refuted[4:20, 0].all() and refuted[5:9, 1].all() and refuted.sum() == 16 + 4
    assert not refuted_labels(backward, forward, AGREE_MM, 20.0).any()
    ones = np.full((F, 2), 0.1)
    joined, counts = join_passes(PassResult(forward, ones), PassResult(backward, ones), 20.0)
    assert np.array_equal(joined.points[:, 1], truth[:, 1])
    labelled = np.isfinite(joined.points[:, 0, 0])
    assert np.array_equal(joined.points[labelled, 0], truth[labelled, 0])
    assert counts["systematic_markers"] == 0
