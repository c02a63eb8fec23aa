"""Motive's rigid bodies in a NatNet recording: decoded, and exported beside the C3D.

The simulated Motive streams the pelvis body fitted to the served markers; what the
recording gives (``bodies_from_recording``, and ``spotlab export --c3d``'s
``.bodies.csv``) must equal that pose as NatNet carries it (float32).
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from spotlab.console.cli import main
from spotlab.core.errors import RecordingError
from spotlab.drivers.natnet.bodies import bodies_from_recording, rotation_matrices
from spotlab.simulators.natnet import NatNetServer
from spotlab.simulators.natnet_scene import NatNetScene, quaternion


def _truth_poses(scene: NatNetScene, truth: Path, frames: np.ndarray) -> tuple[np.ndarray, ...]:
    """Served pelvis position (mm) and quaternion of each frame, as float32 carries them."""
    t = np.load(truth)
    row = {int(k): i for i, k in enumerate(t["frame"])}
    pos, quat = [], []
    for k in frames:
        (pose,) = scene.poses(t["markers_mm"][row[int(k)]])
        pos.append(np.float32(pose.position_m).astype(np.float64) * 1000.0)
        quat.append(np.float32(pose.quaternion).astype(np.float64))
    return np.asarray(pos), np.asarray(quat)


@pytest.mark.parametrize("version", [(4, 1), (3, 1)])
def test_recorded_bodies_equal_the_served_poses_and_export_beside_the_c3d(
    version: tuple[int, int], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    scene = NatNetScene(markers=40, cameras=2, rate_hz=100.0, seed=4)
    out, truth, c3d = tmp_path / "rec.spj", tmp_path / "truth.npz", tmp_path / "rec.c3d"
    with NatNetServer(scene, version=version, truth=truth) as srv:
        code = main(["record", "--device", f"natnet={srv.address}", "--seconds", "1.5",
                     "--out", str(out)])  # fmt: skip
    assert code == 0, capsys.readouterr().err

    got = bodies_from_recording(out)
    b = got.bodies
    assert b.stream == "natnet" and b.names == ("pelvis",)
    assert len(b.seq) >= 120 and np.all(np.diff(b.seq) == 1)
    pos, quat = _truth_poses(scene, truth, b.seq)
    np.testing.assert_array_equal(b.positions[:, 0], pos)
    np.testing.assert_array_equal(got.quaternions[:, 0], quat)
    np.testing.assert_allclose(b.rotations[:, 0], rotation_matrices(quat), atol=1e-12)
    assert np.all(got.mean_error_mm >= 0)

    capsys.readouterr()
    assert main(["export", str(out), "--c3d", str(c3d)]) == 0
    table = tmp_path / "rec.bodies.csv"
    assert f"wrote              {table} ({len(b.seq)} body rows)" in capsys.readouterr().out
    with open(table, newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["frame"] for r in rows] == [str(k) for k in b.seq]
    assert {r["stream"] for r in rows} == {"natnet"} and {r["body"] for r in rows} == {"pelvis"}
    xyz = np.array([[float(r[c]) for c in ("x_mm", "y_mm", "z_mm")] for r in rows])
    q = np.array([[float(r[c]) for c in ("qx", "qy", "qz", "qw")] for r in rows])
    np.testing.assert_allclose(xyz, pos, atol=1e-6)
    np.testing.assert_allclose(q, quat, atol=1e-6)


def test_the_quaternion_to_matrix_inverts_the_simulators_matrix_to_quaternion() -> None:
    rng = np.random.default_rng(0)
    for _ in range(50):
        r, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        r *= np.sign(np.linalg.det(r))
        q = np.asarray(quaternion(r))
        np.testing.assert_allclose(rotation_matrices(q), r, atol=1e-9)


def test_a_recording_without_natnet_names_the_missing_stream(tmp_path: Path) -> None:
    scene = NatNetScene(markers=6, cameras=2, rate_hz=100.0, seed=0)
    out = tmp_path / "rec.spj"
    with NatNetServer(scene) as srv:
        assert main(["record", "--device", f"natnet={srv.address},name=mocap",
                     "--seconds", "0.5", "--out", str(out)]) == 0  # fmt: skip
    with pytest.raises(RecordingError, match="no natnet stream named 'natnet'"):
        bodies_from_recording(out)
    assert bodies_from_recording(out, "mocap").bodies.names == ()  # 6 markers: no pelvis
