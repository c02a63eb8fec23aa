"""A new subject's first labels, end to end, in process: the static trial of subject 5 of
the simulated hub (sim://centroid, --motion static) -> template fit (spotlab-body) -> M0
-> the same subject's ROM trial labelled with M0 -> the final model learnt from it -> the
same subject's walk labelled. The simulator's truth is read only to score, at the end."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from spotlab.core.errors import ReconstructionError
from spotlab.reconstruction.identification import RigGeometry
from spotlab.reconstruction.identification.static_cloud import static_cloud
from spotlab.reconstruction.identification.subject_model import (
    first_model,
    label_trial,
    learn_model,
    subject_template,
)
from spotlab.reconstruction.identification.template import fit_template, load_template
from spotlab.testing.centroid_scene import CentroidScene, centroid_scene

SEED = 5  # subject 5: used by no other test


def _frames(scene: CentroidScene):  # type: ignore[no-untyped-def]
    return ((scene.frame(f), scene.unusable(f)) for f in range(len(scene)))


def _score(
    points: np.ndarray, scene: CentroidScene, labels: tuple[str, ...]
) -> tuple[float, float]:
    """(right over all marker-frames, wrong over reported), 10 mm from the truth."""
    truth = scene.markers_mm[:, [scene.labels.index(x) for x in labels]]
    reported = np.isfinite(points[..., 0])
    near = np.linalg.norm(points - truth, axis=2) < 10.0
    return float((reported & near).mean()), float((reported & ~near).sum() / reported.sum())


@pytest.fixture(scope="module")
def subject() -> dict[str, Any]:
    """The static trial, its template fit, M0 and the subject's own static pose; the ROM
    trial."""
    body = load_template("spotlab-body")
    static = centroid_scene(1.0, 100.0, seed=SEED, motion="static")
    cloud = static_cloud([static.frame(f) for f in range(len(static))], RigGeometry(static.rig))
    fit = fit_template(cloud.points, body)
    m0 = first_model(cloud.points, fit, body)
    start = subject_template(cloud.points, fit, body, m0)
    rom = centroid_scene(6.0, 100.0, seed=SEED, motion="rom")
    return {"body": body, "static": static, "cloud": cloud, "fit": fit, "m0": m0,
            "start": start, "rom": rom}  # fmt: skip


def test_static_then_rom_then_the_walk_of_the_same_subject(subject: dict[str, Any]) -> None:
    body, static, cloud, fit = (subject[k] for k in ("body", "static", "cloud", "fit"))
    m0, start, rom = subject["m0"], subject["start"], subject["rom"]
    labelled, first = label_trial(rom.rig, _frames(rom), m0, start)
    final = learn_model(m0, labelled)
    walk = centroid_scene(3.0, 100.0, seed=SEED)
    walked, _ = label_trial(walk.rig, _frames(walk), final)

    # scored only now
    truth = np.nanmedian(static.markers_mm, axis=0)
    marker_of = np.array([static.labels.index(x) for x in body.labels])
    d = np.linalg.norm(truth[marker_of[fit.marker_of]] - cloud.points, axis=1)
    assert cloud.points.shape[0] == 40 and np.all(fit.marker_of >= 0)
    assert np.all(d < 10.0)  # every static point labelled right
    # Measured (seed 5): scale 1.140, RMS 12.8 mm (marker placement 8 mm per coordinate)
    assert 1.05 < fit.scale < 1.25 and fit.rms_mm < 20.0
    assert first is not None and first.rms_mm < 8.0  # measured 3.4 mm
    right, wrong = _score(labelled, rom, m0.labels)
    assert right > 0.995 and wrong < 0.0005  # measured 100 %, 0
    right, wrong = _score(walked, walk, final.labels)
    # The targets of issue 11: >= 97 % of the marker-frames, <= 0.05 % wrong. Measured
    # 98.65 %, 0 (benchmarks/new_subject.py, seeds 5-8: 97.5-98.9 %, 0).
    assert right > 0.97 and wrong < 0.0005


def test_a_rom_trial_is_labelled_from_where_the_subject_stands_in_the_static_pose(
    subject: dict[str, Any],
) -> None:
    # The ROM's first 2.5 s backwards: the subject moves first and stands still at the
    # end (a recording started late sees the same: the pose comes later, or never).
    rom, m0 = subject["rom"], subject["m0"]
    order = list(range(250, -1, -1))
    frames = [(rom.frame(f), rom.unusable(f)) for f in order]
    labelled, first = label_trial(rom.rig, frames, m0, subject["start"])
    assert first is not None and first.rms_mm <= 5.0 and first.frame >= 100
    truth = rom.markers_mm[order][:, [rom.labels.index(x) for x in m0.labels]]
    reported = np.isfinite(labelled[..., 0])
    wrong = reported & (np.linalg.norm(labelled - truth, axis=2) >= 10.0)
    # Measured: the pose found at frame 145 (RMS 3.4 mm); 100 % labelled, 0 wrong.
    assert reported.mean() > 0.98 and wrong.sum() == 0

    never = [(rom.frame(f), rom.unusable(f)) for f in range(200, 350)]
    with pytest.raises(ReconstructionError, match="fits none of the trial's first"):
        label_trial(rom.rig, never, m0, subject["start"])


def test_a_walk_is_no_static_trial() -> None:
    walk = centroid_scene(0.6, 100.0, seed=SEED)
    with pytest.raises(ReconstructionError, match="not static"):
        static_cloud([walk.frame(f) for f in range(len(walk))], RigGeometry(walk.rig))
