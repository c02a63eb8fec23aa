"""Real easyWand / DLTdv7 coefficients (shared/data/ushichka_dltdv, SOURCES.md section 2c).

DLTdv counts image rows upwards from the bottom edge; Camera.from_dlt(..., v_up=True)
turns its coefficients into a camera that sees the scene, and back exactly. DLTdv7's own
residual xyzres = sqrt(sum of squared reprojection residuals / (2 n_cams - 3)) must follow
from projecting its 3-D points with these cameras (up to the CSV's 6-decimal rounding).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.testing import assert_allclose

from spotlab.geometry import Camera, flip_dlt_v

FOLDER = "ushichka_dltdv/2018-08-17_speaker_playback"
STEM = "DLTdv7_data_2018-08-17_P03_1000TMC"
SIZE = (640, 512)


def _read(path: Path) -> np.ndarray:
    return np.genfromtxt(path, delimiter=",", skip_header=1)


def test_flip_is_an_involution() -> None:
    L = np.arange(1.0, 12.0)
    assert_allclose(flip_dlt_v(flip_dlt_v(L, 512), 512), L, rtol=0, atol=1e-12)


def test_easywand_coefficients(shared_data: Path) -> None:
    folder = shared_data / FOLDER
    coefficients = np.loadtxt(folder / "2018-08-17_wand_dltCoefs_round4.csv", delimiter=",").T
    X = _read(folder / f"{STEM}xyzpts.csv")  # metres
    uv = _read(folder / f"{STEM}xypts.csv").reshape(-1, 3, 2)
    xyzres = _read(folder / f"{STEM}xyzres.csv")
    seen = np.all(np.isfinite(X), axis=1)
    cams = [Camera.from_dlt(L, SIZE, f"cam{i + 1}", v_up=True) for i, L in enumerate(coefficients)]
    squared = np.zeros(int(seen.sum()))
    n_views = np.zeros(int(seen.sum()))
    for cam, L, obs in zip(cams, coefficients, np.moveaxis(uv, 1, 0), strict=True):
        assert_allclose(cam.to_dlt(v_up=True), L, rtol=1e-12, atol=0)
        # easyWand's camera profile: focal 526 px, principal point (320, 256).
        assert abs(cam.K[0, 0] - 526.0) < 3.0
        assert abs(cam.K[0, 2] - 320.0) < 5.0 and abs(cam.K[1, 2] - 256.0) < 5.0
        projected = cam.project(X[seen])
        assert np.all(np.isfinite(projected))  # the scene is in front of every camera
        flipped = obs[seen] * [1.0, -1.0] + [0.0, SIZE[1]]
        resid = np.sum((projected - flipped) ** 2, axis=1)
        has = np.isfinite(resid)
        squared[has] += resid[has]
        n_views += has
    got = np.sqrt(squared / (2 * n_views - 3))
    assert_allclose(got, xyzres[seen], rtol=0, atol=2e-4)  # measured 5.4e-5 px
