"""Fitting a marker template to an unlabelled static point cloud: any heading, body sizes
0.85-1.15, hidden markers, extra points; clouds that are no person standing are refused."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from spotlab.core.errors import ReconstructionError
from spotlab.reconstruction.identification.template import (
    Template,
    fit_template,
    load_template,
    shipped_templates,
    similarity_procrustes,
)


@pytest.fixture(scope="module")
def body() -> Template:
    return load_template("spotlab-body")


def _subject(
    template: Template, yaw_deg: float, scale: float, seed: int, placement_mm: float = 8.0
) -> tuple[np.ndarray, np.ndarray]:
    """The template posed as a subject: scaled about the floor, turned, moved, each marker
    placed off its spot (``placement_mm`` RMS per coordinate); points shuffled. Returns
    the points (M, 3) and the marker of each point."""
    rng = np.random.default_rng(seed)
    a = np.radians(yaw_deg)
    R = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    X = scale * template.neutral_mm @ R.T + [rng.uniform(-800, 800), rng.uniform(-800, 800), 0]
    X = X + rng.normal(0, placement_mm, X.shape)
    order = rng.permutation(X.shape[0])
    return X[order], order


def test_shipped_templates_load_and_round_trip(body: Template, tmp_path: Path) -> None:
    assert {"spotlab-body", "lower-limb"} <= set(shipped_templates())
    assert len(body.labels) == 40 and body.neutral_mm[:, 2].min() >= 0
    body.save(tmp_path / "t.json")
    again = Template.load(tmp_path / "t.json")
    assert again.labels == body.labels and again.links == body.links
    assert np.allclose(again.neutral_mm, body.neutral_mm, atol=0.01)
    with pytest.raises(ReconstructionError, match="no template 'nobody'"):
        load_template("nobody")


def test_similarity_procrustes_recovers_a_transform() -> None:
    rng = np.random.default_rng(1)
    A = rng.normal(0, 300, (10, 3))
    a = 2.0
    R = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    s, R_fit, t = similarity_procrustes(A, 1.1 * A @ R.T + [5, -7, 3])
    assert s == pytest.approx(1.1) and np.allclose(R_fit, R) and np.allclose(t, [5, -7, 3])


@pytest.mark.parametrize("case", range(12))
def test_any_heading_and_body_size(body: Template, case: int) -> None:
    yaw = 30.0 * case + 7.0
    scale = 0.85 + 0.3 * case / 11
    points, marker = _subject(body, yaw, scale, seed=case)
    fit = fit_template(points, body)
    assert np.array_equal(fit.marker_of, marker)  # every point labelled, left and right
    assert (fit.yaw_deg - yaw + 180) % 360 - 180 == pytest.approx(0, abs=3)
    assert fit.scale == pytest.approx(scale, rel=0.03)
    # 8 mm per coordinate of placement: about 14 mm RMS in 3-D
    assert 8.0 < fit.rms_mm < 20.0 and fit.matched == 1.0


def test_hidden_markers_and_extra_points(body: Template) -> None:
    rng = np.random.default_rng(7)
    points, marker = _subject(body, 200.0, 1.1, seed=7)
    keep = rng.permutation(points.shape[0])[:32]  # 8 markers hidden
    extra = np.column_stack([rng.uniform(-2000, 2000, (6, 2)), rng.uniform(0, 50, 6)])
    cloud = np.concatenate([points[keep], extra, [[np.nan] * 3]])
    fit = fit_template(cloud, body)
    assert np.array_equal(fit.marker_of[:32], marker[keep])
    assert np.all(fit.marker_of[32:] == -1)
    assert fit.matched == pytest.approx(32 / 40)
    assert np.isnan(fit.residual_mm).sum() == 8
    labels = fit.labels(body)
    assert labels[0] == body.labels[marker[keep[0]]] and labels[-1] is None


def test_a_cloud_that_is_no_person_is_refused(body: Template) -> None:
    rng = np.random.default_rng(3)
    box = rng.uniform([-1000, -1000, 0], [1000, 1000, 2000], (40, 3))
    with pytest.raises(ReconstructionError, match="do not fit template 'spotlab-body'"):
        fit_template(box, body)
    lframe = np.array([[0, 0, 0], [400, 0, 0], [800, 0, 0], [0, 300, 0]], float) + 10
    with pytest.raises(ReconstructionError, match="markers matched"):
        fit_template(lframe, body)
    with pytest.raises(ReconstructionError, match="need 3 or more"):
        fit_template(np.zeros((2, 3)), body)
    with pytest.raises(ReconstructionError, match="shape"):
        fit_template(np.zeros((5, 2)), body)
