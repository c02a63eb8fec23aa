"""Two tracks on one marker: the unlabelled one is deleted, the labelled one kept."""

from __future__ import annotations

import numpy as np

from spotlab.reconstruction.identification.duplicate_tracks import duplicate_tracks


def test_an_unlabelled_track_on_a_labelled_marker_is_deleted() -> None:
    position = np.array(
        [[0.0, 0.0, 500.0], [0.6, 0.0, 500.0], [100.0, 0.0, 500.0], [101.0, 0.0, 500.0]]
    )
    label = np.array([-1, 3, -1, -1])
    current = np.ones(4, dtype=bool)
    out = duplicate_tracks(position, current, label, apart_mm=4.0)
    # the labelled track keeps the marker; two unlabelled ones are left to the labelling
    assert out.tolist() == [True, False, False, False]
    # a track not measured this frame is not compared; 0 mm turns the rule off
    assert not duplicate_tracks(position, np.array([False, True, True, True]), label, 4.0).any()
    assert not duplicate_tracks(position, current, label, apart_mm=0.0).any()


def test_two_labelled_tracks_are_both_kept() -> None:
    position = np.array([[0.0, 0.0, 500.0], [1.0, 0.0, 500.0]])
    out = duplicate_tracks(position, np.ones(2, bool), np.array([1, 2]), 4.0)
    assert out.tolist() == [False, False]
