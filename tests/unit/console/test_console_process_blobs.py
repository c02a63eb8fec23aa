"""The console's "Process" of a video-centroid trial: the blobs identified with the lab's
marker model (issue 15's processing on the path that needs a model), and the trial's
sidecar told what was done; without a model, a failed job that says why. The rig and
the model are the lab's own (conftest.py): the rig calibrated from wand and L-frame
recordings, the subject's model learnt from its static and range-of-motion recordings;
the trial processed is the same subject walking, and only the final scoring reads the
simulator's truth."""

from __future__ import annotations

import time
from typing import Any

import numpy as np
import pytest
from _centroid_lab import LAB_GROUP, SUBJECT, SubjectLab

import spotlab.simulators  # noqa: F401  (registers sim://)
from spotlab.acquisition.recorder import Recorder
from spotlab.acquisition.session import Session
from spotlab.console.web.processing_jobs import Processor
from spotlab.console.web.trials import TrialInfo, TrialStore
from spotlab.drivers.centroid import CentroidDriver
from spotlab.simulators.centroid_service import CentroidSimOptions, centroid_url_for

# one worker makes the session recordings shared with the other hub tests (conftest.py)
pytestmark = pytest.mark.xdist_group(LAB_GROUP)

RATE_HZ, FRAMES = 300, 150


@pytest.fixture(scope="module")
def lab(tmp_path_factory: pytest.TempPathFactory, subject_lab: SubjectLab) -> dict[str, Any]:
    """A data folder with one recorded hub trial (8 cameras x 40 markers of the subject
    walking, half a second at 300 Hz, no model in its metadata), and the lab's rig and
    marker model files."""
    root = tmp_path_factory.mktemp("console-blobs")
    store = TrialStore(root / "data")
    options = CentroidSimOptions(cameras=8, rate_hz=RATE_HZ, seed=SUBJECT, truth=root / "truth.npz")
    journal = store.journal("S01", "walk", "t1")
    journal.parent.mkdir(parents=True)
    driver = CentroidDriver(centroid_url_for(options), cameras=8, rate_hz=RATE_HZ)
    recorder = Recorder(journal, {"command": "console"})
    with Session([driver], [recorder], close_devices=True) as session:
        deadline = time.monotonic() + 60.0  # the hub's own frames, whatever the load
        while sum(session.status().frames.values()) < FRAMES and time.monotonic() < deadline:
            time.sleep(0.02)
    store.save(TrialInfo("S01", "walk", "t1", state="done"))
    return {"root": root, "store": store, "rig": subject_lab.rig, "model": subject_lab.model}


def _finished(proc: Processor, tid: str) -> dict[str, Any]:
    deadline = time.monotonic() + 120.0
    while (job := proc.job(tid)) is not None and job["state"] == "running":
        assert time.monotonic() < deadline, job
        time.sleep(0.05)
    assert job is not None
    return job


def _process(lab: dict[str, Any], model: Any) -> tuple[Processor, TrialInfo, dict[str, Any]]:
    """Run "Process" on the recorded trial with the lab's rig and ``model``; the (closed)
    processor, the trial and its finished job."""
    proc = Processor(lab["store"], lab["rig"], model, lab["root"] / "lab.toml")
    try:
        info = lab["store"].load("S01.walk.t1")
        proc.submit(info)
        return proc, info, _finished(proc, info.id)
    finally:
        proc.close()


def test_a_hub_trial_is_identified_with_the_labs_model(lab: dict[str, Any]) -> None:
    root, store = lab["root"], lab["store"]
    proc, info, job = _process(lab, lab["model"])
    assert job["state"] == "done" and job["path"] == "identification", job
    result = proc.result(info)
    assert result is not None
    trial = result.trial
    # the labelled points, against the hub's truth only here, at the end (one START:,
    # so C3D frame first_frame + i is hub frame first_frame - 1 + i)
    truth = np.load(root / "truth.npz")
    assert trial.labels == [str(x) for x in truth["labels"]]
    row = {int(f): k for k, f in enumerate(truth["frame_no"])}
    frames = [row[trial.first_frame - 1 + i] for i in range(trial.points.shape[0])]
    true = np.asarray(truth["markers_mm"])[frames]
    seen = np.isfinite(trial.points).all(axis=2)
    assert seen.mean() > 0.97, seen.mean()  # measured 1.0
    error = np.linalg.norm(trial.points[seen] - true[seen], axis=1)
    # measured with the calibrated rig (6 runs): RMS 0.73-0.95 mm, largest 1.4-1.8 mm
    # (with the simulator's true rig and model: RMS 0.21 mm, the centroid noise, 0.93 mm)
    assert np.sqrt(np.mean(error**2)) < 1.2 and error.max() < 3.0, (error.mean(), error.max())
    saved = store.load(info.id).processing
    assert saved is not None and saved["path"] == "identification"
    assert saved["quality"]["frames"] == trial.points.shape[0] >= FRAMES // 2


def test_without_a_model_the_job_fails_and_says_why(lab: dict[str, Any]) -> None:
    _, _, job = _process(lab, None)
    assert job["state"] == "failed" and "model" in job["error"], job
