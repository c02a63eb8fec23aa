"""Marker model and labels by cluster fit."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from spotlab.core.errors import ReconstructionError
from spotlab.reconstruction.identification import MarkerModel
from spotlab.reconstruction.identification.labelling import assign_labels, inconsistent_labels
from spotlab.testing.synthetic_blobs import SyntheticBlobs


def test_infer_finds_the_rigid_segments(scene: SyntheticBlobs) -> None:
    model = MarkerModel.infer(scene.labels, scene.markers_mm[::10])
    found = {frozenset(model.labels[m] for m in seg.markers) for seg in model.segments}
    assert found == {frozenset(v) for v in scene.segments.values()}


def test_model_json_round_trip(model: MarkerModel, tmp_path: Path) -> None:
    model.save(tmp_path / "m.json")
    back = MarkerModel.load(tmp_path / "m.json")
    assert back.labels == model.labels
    np.testing.assert_allclose(back.pairs()[2], model.pairs()[2], atol=1e-3)


def test_a_two_marker_group_is_refused() -> None:
    t = np.linspace(0, 1, 20)
    X = np.zeros((20, 2, 3))
    X[:, 1, 0] = 100.0 + 0 * t
    with pytest.raises(ReconstructionError, match="no rigid cluster of 3"):
        MarkerModel.infer(["A", "B"], X)


def test_labels_from_shape_by_the_smallest_rms(model: MarkerModel, scene: SyntheticBlobs) -> None:
    truth = scene.markers_mm[100]
    rng = np.random.default_rng(0)
    order = rng.permutation(40)
    points = truth[order] + rng.normal(0, 0.3, (40, 3))
    labels = assign_labels(
        model, points, np.full(40, -1, np.intp), tol_mm=5.0, rms_mm=3.0, margin_mm=1.0
    )
    assert (labels == order).mean() >= 0.95  # cold start: nearly all, none wrong
    assert np.all((labels == order) | (labels == -1))


def test_missing_marker_relabelled_from_its_cluster(
    model: MarkerModel, scene: SyntheticBlobs
) -> None:
    truth = scene.markers_mm[50]
    labels = np.arange(40, dtype=np.intp)
    labels[3] = -1  # RPSI lost, its point back as unlabelled
    extra = np.vstack([truth, truth[3] + [0, 0, 40.0]])  # and a decoy 40 mm off
    labels = np.append(labels, -1)
    out = assign_labels(model, extra, labels, tol_mm=5.0, rms_mm=3.0, margin_mm=1.0)
    assert out[3] == 3 and out[40] == -1


def test_swapped_labels_are_dropped(model: MarkerModel, scene: SyntheticBlobs) -> None:
    points = scene.markers_mm[20].copy()
    points[[0, 4]] = points[[4, 0]]  # LASI (pelvis) and C7 (trunk) swapped
    drop = inconsistent_labels(model, points, np.full(40, 100, np.intp), 5.0)
    assert drop[0] and drop[4] and drop.sum() == 2
