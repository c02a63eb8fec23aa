"""Epipolar correspondence of unlabelled blobs across cameras."""

from __future__ import annotations

import numpy as np
import pytest

from spotlab.core.errors import ReconstructionError
from spotlab.geometry import Rig
from spotlab.reconstruction.identification import RigGeometry, match_blobs


def _blobs(rig: Rig, X: np.ndarray, seen: np.ndarray, noise: float, rng: np.random.Generator):
    uv = rig.project(X) + rng.normal(0.0, noise, (len(rig), X.shape[0], 2))
    cam, marker = np.nonzero(seen)
    return uv[cam, marker], cam, marker


def test_clean_blobs_group_by_marker(rig: Rig) -> None:
    rng = np.random.default_rng(0)
    X = rng.uniform([-700, -700, 100], [700, 700, 1700], (40, 3))
    seen = rng.random((8, 40)) < 0.7
    seen[:, :5] = True
    uv, cam, marker = _blobs(rig, X, seen, 0.2, rng)
    geom = RigGeometry(rig)
    xy, ok = geom.normalize(uv, cam)
    assert ok.all()
    found = match_blobs(geom, xy, cam)
    blobs = found.blobs
    for g in range(blobs.shape[1]):
        members = marker[blobs[:, g][blobs[:, g] >= 0]]
        assert np.unique(members).size == 1  # one marker per point
        np.testing.assert_allclose(found.points[g], X[members[0]], atol=3.0)
    assert found.points.shape[0] >= 36
    assert (found.n_cameras >= 3).all()


def test_specks_and_two_camera_coincidences_make_no_points(rig: Rig) -> None:
    rng = np.random.default_rng(1)
    geom = RigGeometry(rig)
    uv = rng.uniform([0, 0], [1279, 1023], (200, 2))
    cam = rng.integers(0, 8, 200)
    xy, _ = geom.normalize(uv, cam)
    found = match_blobs(geom, xy, cam, min_cameras=3)
    assert found.points.shape[0] <= 1  # random specks hardly ever agree in three cameras


def test_reflections_are_consistent_points_below_the_floor(rig: Rig) -> None:
    rng = np.random.default_rng(2)
    X = rng.uniform([-500, -500, 20], [500, 500, 120], (6, 3))
    mirror = X * [1, 1, -1]
    both = np.vstack([X, mirror])
    uv, cam, _ = _blobs(rig, both, np.ones((8, 12), bool), 0.1, rng)
    geom = RigGeometry(rig)
    xy, _ = geom.normalize(uv, cam)
    found = match_blobs(geom, xy, cam)
    assert (found.points[:, 2] < 0).sum() == 6  # the ghosts are found, below the floor


def test_min_cameras_below_two_is_an_error(rig: Rig) -> None:
    geom = RigGeometry(rig)
    with pytest.raises(ReconstructionError, match="min_cameras"):
        match_blobs(geom, np.zeros((0, 2)), np.zeros(0, np.intp), min_cameras=1)
