"""The centroid simulator's calibration scenes: a passive wand waved through the volume, a
static L-frame with its published coordinates, and cameras that stay put between seeds."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from spotlab.console.cli import main
from spotlab.simulators.centroid import CentroidDevice
from spotlab.simulators.centroid_service import (
    WAND_MIDDLE,
    CentroidSimOptions,
    build_centroid_device,
    centroid_options_from_url,
)
from spotlab.simulators.motions import reference_markers


def _device(tmp_path: Path, **kw: Any) -> CentroidDevice:
    return build_centroid_device(CentroidSimOptions(rig_out=tmp_path / "rig.toml", **kw))


def test_the_rig_does_not_depend_on_the_seed(tmp_path: Path) -> None:
    a = _device(tmp_path, seed=0).rig
    for seed, motion, markers in ((7, "walk", 40), (3, "wand", 3), (11, "lframe", 4)):
        b = _device(tmp_path, seed=seed, motion=motion, markers=markers).rig
        for ca, cb in zip(a.cameras, b.cameras, strict=True):
            np.testing.assert_array_equal(ca.K, cb.K)
            np.testing.assert_array_equal(ca.R, cb.R)
            np.testing.assert_array_equal(ca.t, cb.t)
            np.testing.assert_array_equal(ca.dist, cb.dist)


@pytest.mark.parametrize("markers", [2, 3])
def test_the_wand_keeps_its_length_and_middle_and_sweeps_the_volume(
    tmp_path: Path, markers: int
) -> None:
    dev = _device(tmp_path, motion="wand", markers=markers, wand_length_mm=600.0, seed=2)
    X = dev.positions(np.arange(0, 10, 0.01))  # 10 s
    assert X.shape == (1000, markers, 3) and dev.labels[:2] == ("WAND_A", "WAND_B")
    np.testing.assert_allclose(np.linalg.norm(X[:, 1] - X[:, 0], axis=1), 600.0)
    if markers == 3:
        np.testing.assert_allclose(
            np.linalg.norm(X[:, 2] - X[:, 0], axis=1), WAND_MIDDLE * 600.0, rtol=1e-12
        )
    centre = X[:, :2].mean(axis=1)
    span = centre.max(axis=0) - centre.min(axis=0)
    assert (span[:2] > 2000).all() and span[2] > 1200, span  # most of the 3 x 3 x 1.8 m volume
    assert X[..., 2].min() > 0  # above the floor
    # Every camera sees the whole wand in most frames.
    for cam in dev.rig.cameras:
        uv = cam.project(X.reshape(-1, 3)).reshape(X.shape[0], markers, 2)
        inside = ((uv >= 0) & (uv <= np.array(cam.size) - 1)).all(axis=(1, 2))
        assert inside.mean() > 0.9


def test_the_l_frame_is_static_and_its_published_points_are_written(tmp_path: Path) -> None:
    out = tmp_path / "lframe.csv"
    dev = build_centroid_device(
        CentroidSimOptions(motion="lframe", markers=4, frame_points_out=out)
    )
    X = dev.positions(np.array([0.0, 1.0, 5.0]))
    np.testing.assert_array_equal(X[0], X[2])
    lines = out.read_text().splitlines()
    assert lines[0] == "X,Y,Z"
    points = np.array([[float(v) for v in line.split(",")] for line in lines[1:]])
    np.testing.assert_array_equal(points, reference_markers(4).points)
    np.testing.assert_array_equal(points, X[0])
    # A wand or walking body hides nothing behind body segments.
    assert not dev.occluded(X[0], [0, 1]).any()


@pytest.mark.parametrize(
    "query, message",
    [
        ("motion=dance", "motion 'dance'"),
        ("motion=wand&markers=4", "2 to 3 for the wand"),
        ("motion=lframe&markers=2", "3 to 512 for the lframe"),
        ("motion=wand&markers=3&wand_length_mm=20", "wand length"),
    ],
)
def test_bad_scene_options_are_refused(query: str, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        centroid_options_from_url(f"sim://centroid?{query}")


@pytest.mark.parametrize(
    "args, message",
    [
        (
            ["--motion", "gait"],
            "--motion 'gait': the centroid simulator plays walk, static, rom, wand, lframe",
        ),
        (["--motion", "wand", "--markers", "5"], "markers must be 2 to 3 for the wand motion"),
        (["--motion", "wand", "--model-out", "m.json"], "--model-out"),
        (["--motion", "wand", "--wand-length", "10"], "wand length must be 50 to 3000 mm"),
    ],
)
def test_bad_scene_arguments_are_one_clear_line(
    args: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["sim", "centroid", "--pty", *args]) != 0
    err = capsys.readouterr().err
    assert err.count("spotlab: error:") == 1 and message in err, err
