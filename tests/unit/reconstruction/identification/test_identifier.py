"""The Identifier on a walking body: labels, occlusions, dropouts, sunlight, bad calibration."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from spotlab.core.errors import CalibrationError
from spotlab.geometry import Rig
from spotlab.reconstruction.identification import (
    FLOODED,
    NO_BLOBS,
    BlobFrame,
    IdentifiedFrame,
    Identifier,
    MarkerModel,
)
from spotlab.simulators.rigs import ring_rig
from spotlab.testing.synthetic_blobs import SyntheticBlobs


def run(identifier: Identifier, frames: list[Any]) -> tuple[np.ndarray, list[IdentifiedFrame]]:
    """Points (F, M, 3) and results of identifying ``frames`` (BlobFrame, unusable) in turn."""
    results = [identifier(*f) if isinstance(f, tuple) else identifier(f) for f in frames]
    return np.stack([r.points for r in results]), results


def score(points: np.ndarray, truth: np.ndarray, tol_mm: float = 10.0) -> tuple[int, int]:
    """(right, wrong) reported marker-frames."""
    err = np.linalg.norm(points - truth, axis=-1)
    reported = np.isfinite(err)
    return int((reported & (err < tol_mm)).sum()), int((reported & ~(err < tol_mm)).sum())


def test_labels_through_occlusions_merges_and_reflections(
    rig: Rig, scene: SyntheticBlobs, model: MarkerModel
) -> None:
    points, results = run(Identifier(rig, model), [scene.frame(f) for f in range(len(scene))])
    right, wrong = score(points, scene.markers_mm)
    possible = (np.isfinite(scene.clean_uv[..., 0]).sum(axis=0) >= 2).sum()
    assert wrong == 0
    assert right >= 0.99 * possible
    assert sum(r.ghosts for r in results) > 0  # reflections were seen and rejected
    assert scene.merged.any()
    # occluded markers came back with their labels
    full = ~np.isfinite(points[..., 0])
    gaps = (full[1:] & ~full[:-1]).sum()
    last = (np.isfinite(scene.clean_uv[:, -1, :, 0]).sum(axis=0) >= 2).sum()
    assert gaps > 0 and np.isfinite(points[-1, :, 0]).sum() >= last - 1


def _without_camera(frame: BlobFrame, c: int) -> BlobFrame:
    keep = frame.camera != c
    return BlobFrame(frame.uv[keep], frame.camera[keep], frame.merged[keep])


def test_camera_dropping_out_midway(rig: Rig, scene: SyntheticBlobs, model: MarkerModel) -> None:
    frames = [scene.frame(f) for f in range(len(scene))]
    frames[120:] = [_without_camera(f, 2) for f in frames[120:]]
    points, results = run(Identifier(rig, model, check_frames=0), frames)
    right, wrong = score(points, scene.markers_mm)
    assert wrong == 0
    clean = scene.clean_uv.copy()
    clean[2, 120:] = np.nan
    # a marker left with 2 cameras after a gap needs 3 to start a track again
    assert right >= 0.97 * (np.isfinite(clean[..., 0]).sum(axis=0) >= 2).sum()
    assert results[200].camera_flags[2] == NO_BLOBS and results[100].camera_flags[2] == 0


def test_thousands_of_blobs_in_one_camera_are_flagged(
    rig: Rig, scene: SyntheticBlobs, model: MarkerModel
) -> None:
    rng = np.random.default_rng(0)
    frames: list[BlobFrame] = [scene.frame(f) for f in range(len(scene))]
    for f in range(100, 130):  # sunlight on camera 4 for 0.1 s
        sun = rng.uniform([0, 0], [1279, 1023], (3000, 2))
        fr = frames[f]
        frames[f] = BlobFrame(
            np.vstack([fr.uv, sun]),
            np.concatenate([fr.camera, np.full(3000, 4)]),
            np.concatenate([fr.merged, np.zeros(3000, bool)]),
        )
    points, results = run(Identifier(rig, model), frames)
    assert all(results[f].camera_flags[4] == FLOODED for f in range(100, 130))
    assert score(points, scene.markers_mm)[1] == 0
    assert np.isfinite(points[100:130, :, 0]).mean() > 0.9


def test_swapped_cameras_are_a_calibration_error(scene: SyntheticBlobs, model: MarkerModel) -> None:
    cams = list(ring_rig(8).cameras)
    cams[1], cams[5] = cams[5], cams[1]
    identify = Identifier(Rig(cams), model, check_frames=60)
    with pytest.raises(CalibrationError, match=r"does not match the cameras: cam6.*cam2"):
        run(identify, [scene.frame(f) for f in range(len(scene))])


def test_another_rig_is_a_calibration_error(scene: SyntheticBlobs, model: MarkerModel) -> None:
    identify = Identifier(ring_rig(8, seed=7, radius_mm=3500.0), model, check_frames=60)
    with pytest.raises(CalibrationError, match="does not match the cameras"):
        run(identify, [scene.frame(f) for f in range(len(scene))])
