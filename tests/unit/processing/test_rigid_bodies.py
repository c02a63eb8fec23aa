"""One 6D table for both families: ``spotlab export REC --c3d OUT`` writes OUT.bodies.csv.

A recording of the simulated QTM and of the simulated Motive at once: the table holds
both streams' bodies, each as its family's decoder gives them (position mm, quaternion
x, y, z, w from the rotation matrix for QTM, Motive's own for NatNet).
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from spotlab.console.cli import main
from spotlab.drivers.natnet.bodies import bodies_from_recording as natnet_bodies
from spotlab.drivers.natnet.bodies import rotation_matrices
from spotlab.drivers.qualisys import bodies_from_recording as qualisys_bodies
from spotlab.processing.rigid_bodies import quaternions
from spotlab.simulators.natnet import NatNetServer
from spotlab.simulators.natnet_scene import NatNetScene
from spotlab.simulators.qualisys import QualisysServer, QualisysSimOptions


def test_matrix_to_quaternion_and_back() -> None:
    rng = np.random.default_rng(1)
    r = np.stack([np.linalg.qr(rng.normal(size=(3, 3)))[0] for _ in range(100)])
    r *= np.sign(np.linalg.det(r))[:, None, None]
    q = quaternions(r)
    np.testing.assert_allclose(np.linalg.norm(q, axis=-1), 1.0, atol=1e-12)
    assert np.all(q[:, 3] >= 0)
    np.testing.assert_allclose(rotation_matrices(q), r, atol=1e-9)


def test_export_writes_both_families_bodies_in_one_table(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out, c3d = tmp_path / "both.spj", tmp_path / "both.c3d"
    qtm = QualisysSimOptions(markers=40, cameras=2, rate_hz=100.0, seed=2)
    scene = NatNetScene(markers=40, cameras=2, rate_hz=100.0, seed=2)
    with QualisysServer(qtm) as q, NatNetServer(scene) as n:
        code = main(["record", "--device", f"qualisys={q.address}", "--device",
                     f"natnet={n.address}", "--seconds", "2", "--out", str(out)])  # fmt: skip
    assert code == 0, capsys.readouterr().err
    assert main(["export", str(out), "--c3d", str(c3d)]) == 0
    with open(tmp_path / "both.bodies.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    qb, nb = qualisys_bodies(out), natnet_bodies(out)
    for stream, bodies, quats in (
        ("qualisys", qb, quaternions(qb.rotations)),
        ("natnet", nb.bodies, nb.quaternions),
    ):
        mine = [r for r in rows if r["stream"] == stream]
        assert len(bodies.seq) >= 50 and len(mine) == len(bodies.seq) * len(bodies.names)
        assert [r["body"] for r in mine[: len(bodies.names)]] == list(bodies.names)
        xyz = np.array([[float(r[c]) for c in ("x_mm", "y_mm", "z_mm")] for r in mine])
        q = np.array([[float(r[c]) for c in ("qx", "qy", "qz", "qw")] for r in mine])
        np.testing.assert_allclose(xyz, bodies.positions.reshape(-1, 3), atol=1e-6)
        np.testing.assert_allclose(q, quats.reshape(-1, 4), atol=1e-6)
        np.testing.assert_allclose(
            rotation_matrices(q).reshape(bodies.rotations.shape), bodies.rotations, atol=2e-5
        )
