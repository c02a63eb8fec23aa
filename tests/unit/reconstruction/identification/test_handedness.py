"""Flat clusters told from their mirror image by reference markers; glitch-robust ranges."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from spotlab.core.errors import ReconstructionError
from spotlab.reconstruction.identification import Link, MarkerModel
from spotlab.reconstruction.identification.handedness import (
    Reference,
    learn_references,
    misplaced_segments,
    wrong_way_round,
)
from spotlab.reconstruction.identification.labelling import assign_labels
from spotlab.reconstruction.identification.model import Segment
from spotlab.reconstruction.identification.spreads import distance_range, robust_range

#: An isosceles triangle (AB = AC: B and C alike by their distances) and a marker D off
#: its plane, on the side of +z, nearer B than C.
TRIANGLE = np.array([[0.0, 0.0, 0.0], [80.0, 40.0, 0.0], [80.0, -40.0, 0.0]])
D_LOCAL = np.array([40.0, 30.0, 90.0])


def motion(frames: int = 200, seed: int = 0) -> np.ndarray:
    """(F, 4, 3) mm: the triangle A, B, C turning about at random, D wobbling 5 mm."""
    rng = np.random.default_rng(seed)
    R = Rotation.from_rotvec(rng.normal(0.0, 0.6, (frames, 3))).as_matrix()
    local = np.vstack([TRIANGLE, D_LOCAL])
    X = np.einsum("fij,pj->fpi", R, local) + rng.normal(0.0, 300.0, (frames, 1, 3)) + 2000.0
    X[:, 3] += rng.normal(0.0, 5.0, (frames, 3))
    return X


def triangle_model(X: np.ndarray) -> MarkerModel:
    coords = TRIANGLE - TRIANGLE.mean(axis=0)
    segments = ((np.arange(3), coords),)
    refs = learn_references(segments, X, tolerance_mm=5.0)
    seg = Segment("tri", (0, 1, 2), coords)
    links = tuple(Link(m, 3, 0.0, 500.0) for m in range(3))
    return MarkerModel(("A", "B", "C", "D"), (seg,), links, 5.0, 50.0, references=refs)


def test_the_reference_of_a_flat_cluster_is_learnt() -> None:
    X = motion()
    model = triangle_model(X)
    assert len(model.references) == 1
    ref = model.references[0]
    assert (ref.segment, ref.marker) == (0, 3)
    # D's direction in the cluster's frame, a narrow cone (5 mm of wobble at 100 mm)
    expected = (D_LOCAL - TRIANGLE.mean(axis=0)) / np.linalg.norm(D_LOCAL - TRIANGLE.mean(axis=0))
    assert float(ref.direction @ expected) > np.cos(np.radians(3.0))
    assert 0.5 < ref.spread_deg < 10.0
    # and its side of the triangle: (B - A) x (C - A) points to -z, D stands at +z
    assert ref.triple == (0, 1, 2) and ref.side == -1


def test_a_solid_cluster_needs_no_reference() -> None:
    X = motion()
    tetra = ((np.arange(4), np.vstack([TRIANGLE, D_LOCAL]) - 0.0),)
    assert learn_references(tetra, X, tolerance_mm=5.0) == ()


def test_a_mirrored_identity_is_refused_and_dropped() -> None:
    X = motion(50, seed=1)
    model = triangle_model(X)
    frame = X[-1]
    rows = np.array([[0, 1, 2], [0, 2, 1]])  # right, and B and C exchanged
    refused = wrong_way_round(
        model.segments[0].coordinates, list(model.references), frame, rows, np.array([3])
    )
    assert refused.tolist() == [False, True]
    # without D labelled nothing is refused
    none = wrong_way_round(
        model.segments[0].coordinates, list(model.references), frame, rows, np.array([-1])
    )
    assert not none.any()
    # in a labelled frame: the exchanged cluster loses its labels, D keeps its own
    swapped = frame[[0, 2, 1, 3]]
    drop = misplaced_segments(model.segment_arrays, model.sides, swapped)
    assert drop.tolist() == [True, True, True, False]
    ok = misplaced_segments(model.segment_arrays, model.sides, frame)
    assert not ok.any()


def test_the_reference_settles_an_identity_distances_leave_open() -> None:
    X = motion(50, seed=2)
    model = triangle_model(X)
    points = X[-1][[2, 0, 3, 1]]  # C, A, D, B: D labelled, the triangle not
    labels = np.array([-1, -1, 3, -1])
    plain = MarkerModel(model.labels, model.segments, model.links, 5.0, 50.0)
    kw = {"tol_mm": 5.0, "rms_mm": 3.0, "margin_mm": 1.0}
    # by distances alone B and C are alike: ambiguous, left unlabelled
    assert (assign_labels(plain, points, labels, **kw)[[0, 1, 3]] == -1).all()
    assert assign_labels(model, points, labels, **kw).tolist() == [2, 0, 3, 1]


def test_a_flat_cluster_waits_for_its_references_unless_its_lead_is_clear() -> None:
    # AC 3 mm longer than AB: exchanging B and C fits 1.9 mm worse (RMS), a lead above
    # the 1 mm margin, below the 5 mm tolerance
    tri = np.array([[0.0, 0.0, 0.0], [80.0, 40.0, 0.0], [80.0, -46.0, 0.0]])
    coords = tri - tri.mean(axis=0)
    seg = Segment("tri", (0, 1, 2), coords)
    links = tuple(Link(m, 3, 0.0, 500.0) for m in range(3))
    ref = Reference(0, 3, np.array([0.0, 0.0, 1.0]), 10.0)
    checked = MarkerModel(("A", "B", "C", "D"), (seg,), links, 5.0, 50.0, references=(ref,))
    plain = MarkerModel(("A", "B", "C", "D"), (seg,), links, 5.0, 50.0)
    kw = {"tol_mm": 5.0, "rms_mm": 3.0, "margin_mm": 1.0}
    points = tri + 1000.0
    free = np.full(3, -1)
    assert assign_labels(plain, points, free, **kw).tolist() == [0, 1, 2]
    assert assign_labels(checked, points, free, **kw).tolist() == [-1, -1, -1]


def test_references_survive_json(tmp_path: Path) -> None:
    model = triangle_model(motion())
    model.save(tmp_path / "m.json")
    back = MarkerModel.load(tmp_path / "m.json")
    assert len(back.references) == 1
    got, want = back.references[0].direction, model.references[0].direction
    np.testing.assert_allclose(got, want, atol=1e-6)
    assert back.to_json() == model.to_json()
    plain = MarkerModel(model.labels, model.segments, model.links)
    assert "references" not in plain.to_json()


def test_a_reference_on_its_own_cluster_is_refused() -> None:
    model = triangle_model(motion())
    bad = Reference(0, 1, np.array([0.0, 0.0, 1.0]), 5.0)
    with pytest.raises(ReconstructionError, match="its own segment"):
        MarkerModel(model.labels, model.segments, model.links, references=(bad,))


def test_robust_range_leaves_a_glitch_out_and_smooth_data_alone() -> None:
    X = motion(300, seed=3)
    lo, hi = distance_range(X)
    r_lo, r_hi = robust_range(X)
    np.testing.assert_array_equal(r_lo, lo)
    np.testing.assert_array_equal(r_hi, hi)
    # a marker written as (0, 0, 0) for 4 % of the frames (missing, in an old file)
    X[:12, 3] = 0.0
    g_lo, g_hi = robust_range(X)
    clean_lo, clean_hi = distance_range(X[12:])
    np.testing.assert_allclose(g_lo, clean_lo)
    np.testing.assert_allclose(g_hi, clean_hi)
    assert np.nanmax(distance_range(X)[1] - clean_hi) > 100.0
