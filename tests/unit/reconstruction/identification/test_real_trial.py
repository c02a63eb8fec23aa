"""Identification out of sample on a real gait trial: model learnt with defaults from the
first half of bmc/walk1.trc (28 skin markers, 150 Hz), the second half projected into the
8 ring cameras (noise, merges, ghosts, occlusions, dropouts) and labelled cold."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from spotlab.io import labelled_markers, read_trial
from spotlab.reconstruction.identification import Identifier, MarkerModel, model_fit
from spotlab.testing.trial_scene import place_in_volume, trial_scene

DATA = Path(__file__).resolve().parents[4].parent / "shared" / "data"


def _trial() -> tuple[tuple[str, ...], np.ndarray, float]:
    path = DATA / "bmc" / "walk1.trc"
    assert path.is_file(), f"reference data missing: {path}"
    trial = read_trial(path)
    labels, X = labelled_markers(trial, path)
    return labels, X, trial.point_rate


def test_default_model_of_skin_markers_labels_the_other_half() -> None:
    labels, X, rate = _trial()
    assert len(labels) == 28 and X.shape[0] == 364
    h = X.shape[0] // 2
    model = MarkerModel.infer(labels, X[:h])
    # the tolerance comes from the trial's own spreads, not the 2 mm of rigid plates
    assert model.tolerance_mm is not None and 10.0 < model.tolerance_mm < 15.0
    assert model.link_spread_mm is not None and model.link_spread_mm >= 50.0
    assert len(model.segments) >= 3
    placed = place_in_volume(X)
    scene = trial_scene(placed[h:], labels, rate, seed=1, place=False)
    identify = Identifier(scene.rig, model)
    points = np.array([identify(frame).points for frame in scene.frames])
    truth = scene.markers_mm
    err = np.linalg.norm(points - truth, axis=-1)
    reported = np.isfinite(err)
    right = reported & (err < 10.0)
    visible = np.isfinite(truth[..., 0]) & (scene.own_blobs >= 2)
    assert right.sum() / reported.sum() > 0.999  # measured 0.9996
    assert (reported & ~right).sum() / reported.sum() < 0.001  # measured 0.0004
    assert right[visible].mean() > 0.99  # measured 0.999
    assert right.sum() / np.isfinite(truth[..., 0]).sum() > 0.94  # measured 0.949


def test_model_fit_names_a_swapped_label() -> None:
    labels, X, _ = _trial()
    h = X.shape[0] // 2
    model = MarkerModel.infer(labels, X[:h])
    clean = model_fit(model, labels, X[h:])
    assert np.nanmax(clean.rms_mm) < 5.0  # measured 2.8 mm
    a, b = labels.index("R.Heel"), labels.index("L.Heel")
    swapped = X[h:].copy()
    swapped[:, [a, b]] = swapped[:, [b, a]]
    fit = model_fit(model, labels, swapped)
    assert fit.labels[fit.worst] in ("R.Heel", "L.Heel")
    assert fit.rms_mm[fit.worst] > 10 * np.nanmax(clean.rms_mm)
