"""Rig: projection, anipose TOML round trip, the real anipose file, OpenCV YAML export."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.spatial.transform import Rotation

from spotlab.core.errors import CalibrationError
from spotlab.geometry import Camera, Rig

ANIPOSE = "aniposelib_mouse_outdoor/calibration_right_4_10_2026_adjusted.toml"


def _rig() -> Rig:
    rng = np.random.default_rng(0)
    cams = []
    for i in range(3):
        K = [[900.0 + i, 0.5, 320.0], [0.0, 905.0, 250.0], [0.0, 0.0, 1.0]]
        R = Rotation.from_rotvec(rng.normal(size=3) * 0.3).as_matrix()
        cams.append(
            Camera(K, rng.normal(size=5) * 0.01, R, [i * 10.0, 5.0, 2000.0], (640, 512), f"c{i}")
        )
    return Rig(cams)


def test_project_stacks_cameras() -> None:
    rig = _rig()
    X = np.zeros((7, 4, 3))
    uv = rig.project(X)
    assert uv.shape == (3, 7, 4, 2)
    assert_allclose(uv[1], rig.cameras[1].project(X))
    assert rig.names == ["c0", "c1", "c2"]
    assert len(list(rig)) == 3


def test_save_load_round_trip(tmp_path: Path) -> None:
    rig = _rig()
    path = tmp_path / "calibration.toml"
    rig.save(path)
    back = Rig.load(path)
    assert back.names == rig.names
    for a, b in zip(rig, back, strict=True):
        assert_allclose(b.K, a.K, rtol=0, atol=0)
        assert_allclose(b.dist, a.dist, rtol=0, atol=0)
        assert_allclose(b.t, a.t, rtol=0, atol=0)
        assert_allclose(b.R, a.R, rtol=0, atol=1e-15)
        assert b.size == a.size


def test_reads_the_real_anipose_file(shared_data: Path, tmp_path: Path) -> None:
    rig = Rig.load(shared_data / ANIPOSE)
    assert rig.names == [str(n) for n in range(10, 22)]
    cam = rig.cameras[0]
    assert cam.size == (640, 512)
    assert_allclose(cam.K, [[527.226, 0.0, 316.4491], [0.0, 525.9586, 252.6574], [0, 0, 1]])
    assert_allclose(cam.dist, [-0.3437, 0.1788, 0.0, 0.0, -0.0527])
    rvec = [0.060474844310914926, -0.04799192177943883, -0.19979243433107793]
    assert_allclose(cam.R, Rotation.from_rotvec(rvec).as_matrix())
    assert_allclose(cam.t, [0.19647572394207602, -0.004468418573554182, 0.09406292633374266])
    # The detections of the same data set land inside the images.
    p2d = np.load(shared_data / "aniposelib_mouse_outdoor/points_right_4_10_2026_sub.npz")["p2d"]
    assert p2d.shape[0] == len(rig)
    rig.save(tmp_path / "again.toml")
    again = Rig.load(tmp_path / "again.toml")
    for a, b in zip(rig, again, strict=True):
        assert_allclose(b.R, a.R, rtol=0, atol=1e-15)
        assert_allclose(b.t, a.t, rtol=0, atol=0)


def test_table_order_beyond_ten_cameras(shared_data: Path, tmp_path: Path) -> None:
    path = shared_data / ANIPOSE
    sorted_names = Rig.load(path, sort_tables=True).names
    assert sorted_names[:4] == ["10", "11", "20", "21"]  # cam_0, cam_1, cam_10, cam_11
    rig = Rig.load(path)
    rig.save(tmp_path / "padded.toml")
    assert "[cam_00]" in (tmp_path / "padded.toml").read_text()
    # Zero-padded keys: anipose's sorted reading and the file order agree.
    assert Rig.load(tmp_path / "padded.toml", sort_tables=True).names == rig.names


def test_pose2sim_four_distortions(tmp_path: Path) -> None:
    path = tmp_path / "p2s.toml"
    path.write_text(
        '[int_cam01_img]\nname = "cam01"\nsize = [ 1920.0, 1080.0,]\n'
        "matrix = [ [ 1000.0, 0.0, 960.0,], [ 0.0, 1000.0, 540.0,], [ 0.0, 0.0, 1.0,],]\n"
        "distortions = [ -0.1, 0.01, 0.0, 0.0,]\nrotation = [ 0.0, 0.0, 0.0,]\n"
        "translation = [ 0.0, 0.0, 3.0,]\nfisheye = false\n\n[metadata]\nadjusted = false\n"
    )
    rig = Rig.load(path)
    assert rig.cameras[0].size == (1920, 1080)
    assert_allclose(rig.cameras[0].dist, [-0.1, 0.01, 0.0, 0.0, 0.0])


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("not = [toml", "not a valid TOML"),
        ("[metadata]\n", "no camera"),
        ('[cam_0]\nname = "a"\n', "lacks the field"),
        (
            "[cam_0]\nsize = [1, 1]\nmatrix = [[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0]]\n"
            "distortions = [0, 0, 0, 0, 0]\nrotation = [0, 0]\ntranslation = [0, 0, 1]\n",
            "cam_0.*rotation",
        ),
    ],
)
def test_load_errors(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(CalibrationError, match=message):
        Rig.load(path)


def test_empty_rig() -> None:
    with pytest.raises(CalibrationError, match="at least one"):
        Rig([])
    with pytest.raises(CalibrationError, match="not a Camera"):
        Rig([object()])  # type: ignore[list-item]


def test_opencv_yaml_export(tmp_path: Path) -> None:
    rig = _rig()
    path = tmp_path / "rig.yml"
    rig.to_opencv_yaml(path)
    text = path.read_text()
    assert text.startswith("%YAML:1.0\n---\n")
    blocks = re.findall(
        r"(\w+): !!opencv-matrix\n\s+rows: (\d+)\n\s+cols: (\d+)\n\s+dt: d\n\s+data: \[(.*)\]", text
    )
    assert len(blocks) == 5 * len(rig)
    by_cam = [blocks[i * 5 : (i + 1) * 5] for i in range(len(rig))]
    for cam, cam_blocks in zip(rig, by_cam, strict=True):
        values = {
            name: np.array([float(v) for v in data.split(",")]) for name, _, _, data in cam_blocks
        }
        assert_allclose(values["camera_matrix"].reshape(3, 3), cam.K, rtol=0, atol=0)
        assert_allclose(values["distortion_coefficients"], cam.dist, rtol=0, atol=0)
        assert_allclose(values["rotation_matrix"].reshape(3, 3), cam.R, rtol=0, atol=0)
        assert_allclose(values["tvec"], cam.t, rtol=0, atol=0)
