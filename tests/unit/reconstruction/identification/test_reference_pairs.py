"""Two link-only markers exchanged are put back by the directions a cluster sees them in."""

from __future__ import annotations

import numpy as np

from spotlab.reconstruction.identification import Link, MarkerModel, Segment
from spotlab.reconstruction.identification.handedness import Reference
from spotlab.reconstruction.identification.reference_pairs import (
    exchanged_references,
    reference_pairs,
)

TRIANGLE = np.array([[0.0, 0.0, 0.0], [120.0, 0.0, 0.0], [40.0, 90.0, 0.0]])


def _unit(v: list[float]) -> np.ndarray:
    a = np.array(v)
    return a / np.linalg.norm(a)


def _model() -> MarkerModel:
    """A flat cluster (a shank) and two forefoot markers on no cluster, 11 degrees apart
    as seen from it, each in a 6-degree cone; their distances (links) alike."""
    coords = TRIANGLE - TRIANGLE.mean(axis=0)
    links = tuple(Link(m, k, 150.0, 400.0) for m in (3, 4) for k in (0, 1, 2))
    refs = (
        Reference(0, 3, _unit([0.2, 0.1, -1.0]), 6.0, (0, 1, 2), 0),
        Reference(0, 4, _unit([0.4, 0.1, -1.0]), 6.0, (0, 1, 2), 0),
    )
    return MarkerModel(
        ("A", "B", "C", "MET1", "MET5"),
        (Segment("shank", (0, 1, 2), coords),),
        (*links, Link(3, 4, 30.0, 90.0)),
        references=refs,
    )


def _frame(model: MarkerModel, turn_deg: float) -> np.ndarray:
    """The five points, the cluster turned about z and moved, the forefoot where its
    cones point (at 250 and 260 mm)."""
    c, s = np.cos(np.radians(turn_deg)), np.sin(np.radians(turn_deg))
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    t = np.array([500.0, -200.0, 900.0])
    coords = model.segments[0].coordinates
    out = np.empty((5, 3))
    out[:3] = coords @ R.T + t
    out[3] = R @ (250.0 * model.references[0].direction) + t
    out[4] = R @ (260.0 * model.references[1].direction) + t
    return out


def test_the_exchanged_pair_is_found_and_the_right_one_left() -> None:
    model = _model()
    table = reference_pairs(model)
    assert len(table) == 1 and table[0].marker.tolist() == [3, 4]
    assert (table[0].first.tolist(), table[0].second.tolist()) == ([0], [1])
    for turn in (0.0, 35.0, -120.0):
        points = _frame(model, turn)
        assert exchanged_references(model, table, points) == []
        assert exchanged_references(model, table, points[[0, 1, 2, 4, 3]]) == [(3, 4)]


def test_nothing_without_the_cluster_or_both_markers() -> None:
    model = _model()
    table = reference_pairs(model)
    swapped = _frame(model, 10.0)[[0, 1, 2, 4, 3]]
    two = swapped.copy()
    two[1] = np.nan  # two cluster markers: no frame to see from
    assert exchanged_references(model, table, two) == []
    one = swapped.copy()
    one[3] = np.nan
    assert exchanged_references(model, table, one) == []
