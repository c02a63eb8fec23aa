"""dlt_calibrate on the measured DLT cube (shared/data/dlt_cube_duarte, SOURCES.md section 2b).

Published answers (dltx / Duarte's DLTx test thresholds): per-view calibration residual
below 3.0, 3.1, 6.5, 3.0 px; mean 3-D reconstruction error of the 8 cube corners from
all 4 views below 0.11 cm. The cube is given in cm; the DLT is unit-free, so the test
works in cm like the reference.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose

from spotlab.calibration import dlt_calibrate
from spotlab.geometry import Rig
from spotlab.reconstruction import triangulate

RESIDUAL_LIMITS_PX = (3.0, 3.1, 6.5, 3.0)


def _load(shared_data: Path, name: str) -> np.ndarray:
    return np.loadtxt(shared_data / "dlt_cube_duarte" / name, delimiter=",", skiprows=1)


def _triangulate_least_squares(coefficients: list[np.ndarray], uv: list[np.ndarray]) -> np.ndarray:
    """DLT reconstruction, Woltring & Huiskes Eq. 7-8 (linear least squares in X)."""
    rows, rhs = [], []
    for L, (u, v) in zip(coefficients, uv, strict=True):
        rows.append(L[0:3] - u * L[8:11])
        rhs.append(u - L[3])
        rows.append(L[4:7] - v * L[8:11])
        rhs.append(v - L[7])
    return np.linalg.lstsq(np.array(rows), np.array(rhs), rcond=None)[0]


def _triangulate_homogeneous(coefficients: list[np.ndarray], uv: list[np.ndarray]) -> np.ndarray:
    """The homogeneous SVD form used by dltx's dlt_reconstruct (unit dependent)."""
    rows = []
    for L, (u, v) in zip(coefficients, uv, strict=True):
        L12 = np.append(L, 1.0)
        rows.append(L12[0:4] - u * L12[8:12])
        rows.append(L12[4:8] - v * L12[8:12])
    vt = np.linalg.svd(np.array(rows))[2]
    return vt[-1, :3] / vt[-1, 3]


@pytest.mark.parametrize("refine", [True, False])
def test_cube_four_views_reproduce_published_answers(shared_data: Path, refine: bool) -> None:
    data = _load(shared_data, "cube_3d_4views.csv")
    X = data[:, 1:4]  # cm
    views = [data[:, 4 + 2 * c : 6 + 2 * c] for c in range(4)]
    results = [dlt_calibrate(X, uv, refine=refine) for uv in views]
    for res, limit in zip(results, RESIDUAL_LIMITS_PX, strict=True):
        assert res.rms_px < limit
        assert res.rms_px <= res.linear_rms_px + 1e-9
    coefficients = [res.coefficients for res in results]
    for solve in (_triangulate_least_squares, _triangulate_homogeneous):
        rec = np.array([solve(coefficients, [uv[i] for uv in views]) for i in range(8)])
        mean_error_cm = float(np.mean(np.linalg.norm(rec - X, axis=1)))
        assert mean_error_cm < 0.11


def test_readme_six_points_two_cameras(shared_data: Path) -> None:
    # dltx README: point 1 reconstructed from both cameras with the normalised linear DLT
    # is [-0.131704156, 0.871539661, 2549.75288] mm (true [0, 0, 2550]). Its world frame
    # has the opposite handedness of the image axes, which no camera with a proper
    # rotation represents: mirror Z for the calibration and back for the answer.
    data = _load(shared_data, "dltx_readme_6points_2cams.csv")
    mirror = np.array([1.0, 1.0, -1.0])
    X = data[:, 1:4] * mirror
    cams = [dlt_calibrate(X, data[:, 4 + 2 * c : 6 + 2 * c], refine=False) for c in range(2)]
    point = _triangulate_homogeneous([r.coefficients for r in cams], [data[0, 4:6], data[0, 6:8]])
    assert_allclose(point * mirror, [-0.131704156, 0.871539661, 2549.75288], rtol=0, atol=1e-3)


def test_cube_with_spotlab_triangulation(shared_data: Path) -> None:
    """The published bound (mean 3-D error < 0.11 cm) with spotlab's own ``triangulate``
    on the default (adjusted) DLT cameras: the default estimator (odle) and plain least
    squares (Eq. 8) meet it; the re-weighted DLT lands just above (0.1106 cm measured),
    far below the cube's measurement accuracy of +-0.2 cm (docs/methods.md)."""
    data = _load(shared_data, "cube_3d_4views.csv")
    X = data[:, 1:4]  # cm
    views = np.stack([data[:, 4 + 2 * c : 6 + 2 * c] for c in range(4)])  # (C, N, 2)
    rig = Rig([dlt_calibrate(X, uv).camera for uv in views])

    def mean_error_cm(method: str, **options: int) -> float:
        found = triangulate(rig, views, method, **options)  # type: ignore[arg-type]
        return float(np.mean(np.linalg.norm(found - X, axis=1)))

    assert mean_error_cm("odle") < 0.11  # measured 0.1090 cm (the default)
    assert mean_error_cm("dlt", iterations=0) < 0.11  # measured 0.1088 cm
    assert 0.11 < mean_error_cm("dlt") < 0.111  # measured 0.1106 cm: over the bound
