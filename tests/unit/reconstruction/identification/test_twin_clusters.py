"""Twin clusters (two hands' triangles alike) refuted by the links of a marker off them."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from spotlab.reconstruction.identification import Link, MarkerModel
from spotlab.reconstruction.identification.model import Segment
from spotlab.reconstruction.identification.twin_clusters import refuted_twins, twin_segments

#: Left hand L0 L1 L2, right hand R0 R1 R2 (its mirror image in x = 0), an elbow E over
#: the left hand, three trunk markers A B C (mm).
LEFT = np.array([[-300.0, 0.0, 0.0], [-300.0, 70.0, 0.0], [-380.0, 20.0, 0.0]])
RIGHT = LEFT * np.array([-1.0, 1.0, 1.0])
ELBOW = np.array([[-300.0, 0.0, 260.0]])
TRUNK = np.array([[0.0, 0.0, 600.0], [80.0, 0.0, 600.0], [0.0, 80.0, 600.0]])
TRUE = np.vstack([LEFT, RIGHT, ELBOW, TRUNK])  # (10, 3) in model order
LABELS = ("L0", "L1", "L2", "R0", "R1", "R2", "E", "A", "B", "C")


def hands_model(right: np.ndarray = RIGHT, trunk_mm: float = 20.0) -> MarkerModel:
    """The two hands as clusters; E linked to the left hand (its distances +- 20 mm) and
    the trunk (+- ``trunk_mm``), the trunk markers linked to each other."""
    segments = (
        Segment("left", (0, 1, 2), LEFT - LEFT.mean(axis=0)),
        Segment("right", (3, 4, 5), right - right.mean(axis=0)),
    )
    pairs = [(6, m) for m in (0, 1, 2, 7, 8, 9)] + [(7, 8), (7, 9), (8, 9)]
    links = tuple(
        Link(a, b, float(d - w), float(d + w))
        for a, b in pairs
        for d in [np.linalg.norm(TRUE[a] - TRUE[b])]
        for w in [20.0 if b < 3 else trunk_mm]
    )
    return MarkerModel(LABELS, segments, links, 5.0, 50.0)


def test_mirror_image_clusters_are_twins_and_others_not() -> None:
    assert twin_segments(hands_model(), tol_mm=5.0) == (0, 1)
    stretched = RIGHT.copy()
    stretched[2, 0] += 30.0  # the right hand's third marker 30 mm further out
    assert twin_segments(hands_model(stretched), tol_mm=5.0) == ()


def test_the_left_identity_on_the_right_hand_is_refuted_by_the_elbow() -> None:
    model = hands_model()
    twins = twin_segments(model, tol_mm=5.0)
    points = np.full((10, 3), np.nan)
    points[7:] = TRUNK
    # the left cluster's labels on the right hand's points: its shape fits them exactly
    points[:3] = RIGHT
    free = np.vstack([ELBOW, LEFT])  # the elbow and the left hand, unlabelled
    drop = refuted_twins(model, twins, points, free, tol_mm=5.0)
    assert drop.tolist() == [True] * 3 + [False] * 7
    # labelled rightly: the elbow's point is within its links to the left hand
    points[:3] = LEFT
    free = np.vstack([ELBOW, RIGHT])
    assert not refuted_twins(model, twins, points, free, tol_mm=5.0).any()


def test_no_refutation_without_enough_links_elsewhere_or_with_two_candidates() -> None:
    model = hands_model()
    twins = twin_segments(model, tol_mm=5.0)
    points = np.full((10, 3), np.nan)
    points[:3] = RIGHT
    points[7:9] = TRUNK[:2]  # two trunk markers labelled: the elbow has 2 links elsewhere
    free = np.vstack([ELBOW, LEFT, TRUNK[2:]])
    assert not refuted_twins(model, twins, points, free, tol_mm=5.0).any()
    points[9] = TRUNK[2]
    # a second point fitting the elbow's trunk links: which is the elbow is not known
    free = np.vstack([ELBOW, ELBOW + np.array([0.0, 0.0, 8.0]), LEFT])
    assert not refuted_twins(model, twins, points, free, tol_mm=5.0).any()


def test_a_link_exceeded_within_the_rigid_tolerance_or_a_second_track_refutes_nothing() -> None:
    model = hands_model(trunk_mm=60.0)
    twins = twin_segments(model, tol_mm=5.0)
    points = np.full((10, 3), np.nan)
    points[7:] = TRUNK
    points[:3] = LEFT  # labelled rightly
    # the elbow 40 mm further up: 15-20 mm beyond its links to the left hand, within
    # the trunk's; beyond a rigid tolerance of 5 mm, within one of 30 mm
    raised = ELBOW + np.array([0.0, 0.0, 40.0])
    assert refuted_twins(model, twins, points, raised, tol_mm=5.0).sum() == 3
    loose = replace(model, tolerance_mm=30.0)
    assert not refuted_twins(loose, twins, points, raised, tol_mm=5.0).any()
    # a free point on a labelled one (a second track of it) is no marker of its own
    points[:3] = RIGHT
    assert refuted_twins(model, twins, points, ELBOW, tol_mm=5.0).sum() == 3
    points[2] = ELBOW[0] + 2.0
    assert not refuted_twins(model, twins, points, ELBOW, tol_mm=5.0).any()
