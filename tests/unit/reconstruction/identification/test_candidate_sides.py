"""A flat cluster's mirror identity refused by its references' sides when it is chosen."""

from __future__ import annotations

import numpy as np

from spotlab.reconstruction.identification import Link, MarkerModel
from spotlab.reconstruction.identification.candidate_sides import turned_over
from spotlab.reconstruction.identification.handedness import Reference, wrong_way_round
from spotlab.reconstruction.identification.labelling import assign_labels
from spotlab.reconstruction.identification.model import Segment

#: An isosceles triangle (AB = AC, its axis of symmetry along x) and a reference D near
#: that axis, 60 mm below the triangle's plane: the half turn about the axis that fits
#: the mirror identity (B and C exchanged) moves D's direction by 15°, inside its cone.
TRIANGLE = np.array([[0.0, 0.0, 0.0], [80.0, 40.0, 0.0], [80.0, -40.0, 0.0]])
D = np.array([500.0, 0.0, -60.0])


def model() -> MarkerModel:
    centre = TRIANGLE.mean(axis=0)
    seg = Segment("tri", (0, 1, 2), TRIANGLE - centre)
    axis = (D - centre) / np.linalg.norm(D - centre)
    # (B - A) x (C - A) points to -z; D stands at -z: side +1
    ref = Reference(0, 3, axis, 3.0, (0, 1, 2), 1)
    links = tuple(Link(m, 3, 0.0, 1000.0) for m in range(3))
    return MarkerModel(("A", "B", "C", "D"), (seg,), links, 5.0, 50.0, references=(ref,))


def test_the_mirror_identity_is_turned_over_where_the_cone_cannot_tell() -> None:
    m = model()
    points = np.vstack([TRIANGLE, D]) + 1000.0
    rows = np.array([[0, 1, 2], [0, 2, 1]])  # right, and B and C exchanged
    refs = list(m.references)
    cones = wrong_way_round(m.segments[0].coordinates, refs, points, rows, np.array([3]))
    assert not cones.any()  # the cone test is blind here
    sides = turned_over(np.array([0, 1, 2]), refs, points, rows, np.array([3]))
    assert sides.tolist() == [False, True]
    # a reference not labelled, or a candidate missing a corner, says nothing
    assert not turned_over(np.array([0, 1, 2]), refs, points, rows, np.array([-1])).any()
    part = np.array([[0, 2, -1]])
    assert not turned_over(np.array([0, 1, 2]), refs, points, part, np.array([3])).any()


def test_the_reference_s_side_settles_the_identity() -> None:
    points = np.vstack([TRIANGLE[[2, 0, 1]], D]) + 1000.0  # C, A, B, then D labelled
    labels = np.array([-1, -1, -1, 3])
    out = assign_labels(model(), points, labels, tol_mm=5.0, rms_mm=3.0, margin_mm=1.0)
    assert out.tolist() == [2, 0, 1, 3]
