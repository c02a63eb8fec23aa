"""Session recordings shared by the console's video-centroid tests (_centroid_lab.py):
a module using them is marked ``pytest.mark.xdist_group(LAB_GROUP)`` so that ``make
test`` (``--dist loadgroup``) makes them once, on one worker. The true rig
(``rig.toml`` of :func:`calibration_recordings`) is written for scoring only.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest
from _centroid_lab import (
    MODEL_RATE_HZ,
    ROM_S,
    STATIC_S,
    SUBJECT,
    SubjectLab,
    calibrated_rig,
    lab_model,
    record,
)

from spotlab.geometry import Rig
from spotlab.simulators.centroid_service import CentroidSimOptions


@pytest.fixture(scope="session")
def calibration_recordings(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``wand.spj`` (1.5 s of a 3-marker wand at 100 Hz), ``frame.spj`` (0.5 s of the
    L-frame), ``lframe.csv`` (its published points), ``rig.toml`` (the true rig, for
    scoring only)."""
    path = tmp_path_factory.mktemp("blob-calibration")
    for name, seconds, motion, markers in (("wand", 1.5, "wand", 3), ("frame", 0.5, "lframe", 4)):
        options = CentroidSimOptions(
            cameras=8, rate_hz=100, seed=4, motion=motion, markers=markers,
            rig_out=path / "rig.toml", frame_points_out=path / "lframe.csv",
        )  # fmt: skip
        record(path / f"{name}.spj", seconds, options)
    return path


def _record_subject(path: Path) -> None:
    """``static.spj`` and ``rom.spj`` of subject :data:`SUBJECT` into ``path``."""
    for name, motion, seconds in (("static", "static", STATIC_S), ("rom", "rom", ROM_S)):
        options = CentroidSimOptions(rate_hz=MODEL_RATE_HZ, seed=SUBJECT, motion=motion)
        record(path / f"{name}.spj", seconds, options)


@pytest.fixture(scope="session")
def subject_lab(
    tmp_path_factory: pytest.TempPathFactory, calibration_recordings: Path
) -> SubjectLab:
    """The calibrated rig and subject :data:`SUBJECT`'s model learnt with it (the
    subject's recordings made while the rig is calibrated: they wait on the hub's
    clock, the calibration on the CPU)."""
    path = tmp_path_factory.mktemp("subject-lab")
    rig = path / "rig.toml"
    with ThreadPoolExecutor(1) as pool:
        recorded = pool.submit(_record_subject, path)
        calibrated_rig(calibration_recordings).save(rig)
        recorded.result()
    model = path / "model.json"
    lab_model(path / "static.spj", path / "rom.spj", Rig.load(rig)).save(model)
    return SubjectLab(rig, model)
