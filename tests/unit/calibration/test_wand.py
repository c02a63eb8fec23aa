"""wand_calibrate: cold start to the noise floor, the world frame, outliers, bad input."""

from __future__ import annotations

import json

import numpy as np
import pytest

from spotlab.calibration import wand_calibrate, write_report_figure
from spotlab.core.errors import CalibrationError
from spotlab.geometry import Camera, Rig
from spotlab.simulators.rigs import look_at, ring_rig
from spotlab.simulators.wand_dance import WandDance, wand_dance
from spotlab.testing.rig_score import score_rig


def _scene(seed: int = 0, noise: float = 0.2, cameras: int = 4, frames: int = 600, **kw):
    rig = ring_rig(cameras, seed=seed)
    return wand_dance(
        rig, n_frames=frames, noise_px=noise, held_out_frames=300, body_frames=60, seed=seed, **kw
    )


def _calibrate(d: WandDance, **kw):
    return wand_calibrate(d.wand, d.wand_length, d.frame, d.frame_points, (1280, 1024), **kw)


def _scores(rig: Rig, d: WandDance, *, aligned: bool = False) -> np.ndarray:
    """Held-out wand length RMS (mm), body 3-D RMS (mm), held-out reprojection RMS (px)."""
    return np.array(list(score_rig(rig, d, aligned=aligned).values()))


def test_noise_free_data_give_the_true_rig_exactly() -> None:
    d = _scene(noise=0.0, frame_samples=1)
    result = _calibrate(d)
    for est, true in zip(result.rig, d.rig, strict=True):
        np.testing.assert_allclose(est.K, true.K, atol=1e-4)
        np.testing.assert_allclose(est.dist, true.dist, atol=1e-6)
        np.testing.assert_allclose(est.R, true.R, atol=1e-8)
        np.testing.assert_allclose(est.center, true.center, atol=1e-4)
    assert result.report["reprojection_rms_px"] < 1e-5


def test_cold_start_reaches_the_noise_floor_in_the_world_frame() -> None:
    d = _scene(seed=3, cameras=8, frames=1500)
    # The scene's lenses carry all five terms, k3 and the tangential ones small (k3
    # -0.003 to -0.016, p up to 5e-4): the automatic choice leaves some out (their
    # estimates are < 3 standard errors from 1000 frames) and the orientation then
    # misses by up to 0.055 degrees; the full model, asked for, reaches the floor.
    result = _calibrate(d, distortion="full")
    floor = _scores(d.rig, d)
    # Shape of the reconstruction: at the floor (benchmarks/wand_calibration.py measures
    # the reference scene of 3000 frames; this smaller one leaves a little more).
    assert np.all(_scores(result.rig, d, aligned=True) <= 1.05 * floor)
    # Its placement in the world: the reference object fixes it to a fraction of a mm.
    assert _scores(result.rig, d)[1] <= 1.15 * floor[1]
    for est, true in zip(result.rig, d.rig, strict=True):
        assert np.linalg.norm(est.center - true.center) < 3.0
        angle = np.degrees(np.arccos(np.clip((np.trace(est.R @ true.R.T) - 1) / 2, -1, 1)))
        assert angle < 0.05


def test_report_is_plain_data_with_the_promised_figures(tmp_path) -> None:
    d = _scene(seed=1)
    result = _calibrate(d)
    report = json.loads(json.dumps(result.report))
    assert [c["name"] for c in report["cameras"]] == ["cam1", "cam2", "cam3", "cam4"]
    for cam in report["cameras"]:
        assert 0.15 < cam["reprojection_rms_px"] < 0.25  # 0.2 px noise per coordinate
        assert 0.0 < cam["image_coverage"] <= 1.0
    assert abs(report["wand"]["mean_mm"] - 500.0) < 0.2
    assert 0.1 < report["wand"]["sd_mm"] < 2.0
    assert report["verdict"]["grade"] in {"good", "acceptable"}
    png = write_report_figure(
        result.rig, d.wand, result.wand_residuals, result.inliers, result.report, tmp_path / "q.png"
    )
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_gross_outliers_are_rejected_and_do_not_bias_the_rig() -> None:
    d = _scene(seed=2)
    clean = _scores(_calibrate(d).rig, d, aligned=True)
    wand = d.wand.copy()
    rng = np.random.default_rng(7)
    seen = np.argwhere(np.all(np.isfinite(wand), axis=-1))
    bad = seen[rng.choice(len(seen), size=len(seen) // 100, replace=False)]
    wand[bad[:, 0], bad[:, 1], bad[:, 2]] += rng.uniform(15.0, 40.0, (len(bad), 2))
    result = wand_calibrate(wand, d.wand_length, d.frame, d.frame_points, (1280, 1024))
    rejected = ~result.inliers[bad[:, 0], bad[:, 1], bad[:, 2]]
    assert rejected.mean() > 0.99
    assert np.all(_scores(result.rig, d, aligned=True) <= 1.03 * clean)


def test_a_triad_reference_object_works_too() -> None:
    d = _scene(seed=4, frame="triad")
    result = _calibrate(d)
    assert np.all(_scores(result.rig, d, aligned=True) <= 1.1 * _scores(d.rig, d))


def test_progress_reports_each_stage() -> None:
    messages: list[str] = []
    _calibrate(_scene(seed=5, frames=200), progress=messages.append)
    assert messages[0].startswith("cold start")
    assert any("outliers rejected" in m for m in messages)


@pytest.fixture(scope="module")
def small() -> WandDance:
    return _scene(seed=6, frames=200)


def test_a_camera_that_never_sees_the_wand_is_named(small: WandDance) -> None:
    wand = small.wand.copy()
    wand[:, 2] = np.nan
    with pytest.raises(CalibrationError, match=r"camera\(s\) 3 never see the wand"):
        wand_calibrate(wand, 500.0, small.frame, small.frame_points, (1280, 1024))


def test_no_frame_seen_by_two_cameras(small: WandDance) -> None:
    wand = np.full_like(small.wand, np.nan)
    for c in range(4):
        wand[c::4, c] = small.wand[c::4, c]
    with pytest.raises(CalibrationError, match="no frame in which two cameras see both"):
        wand_calibrate(wand, 500.0, small.frame, small.frame_points, (1280, 1024))


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda a: {**a, "wand": a["wand"][..., 0]}, "wand must have shape"),
        (lambda a: {**a, "wand_length": -5.0}, "wand_length must be a positive"),
        (lambda a: {**a, "wand_length": float("nan")}, "wand_length must be a positive"),
        (lambda a: {**a, "frame_points": a["frame_points"] * np.nan}, "frame_points contains NaN"),
        (lambda a: {**a, "frame": a["frame"][:2]}, "frame must have shape"),
        (lambda a: {**a, "wand": a["wand"] * np.inf}, "infinite"),
        (lambda a: {**a, "image_size": (1280, -3)}, "image_size"),
        (lambda a: {**a, "wand": a["wand"][:, :1]}, ">= 2 cameras"),
        (lambda a: {**a, "frame": a["frame"] * np.nan}, "reference object"),
        (
            lambda a: {**a, "frame_points": np.outer(np.arange(5.0), [100.0, 0, 0])},
            "collinear",
        ),
    ],
)
def test_bad_input_names_the_cause(small: WandDance, change, message: str) -> None:
    args = {
        "wand": small.wand,
        "wand_length": 500.0,
        "frame": small.frame,
        "frame_points": small.frame_points,
        "image_size": (1280, 1024),
    }
    with pytest.raises(CalibrationError, match=message):
        wand_calibrate(**change(args))


def test_cameras_in_one_place_are_refused() -> None:
    centre = (3000.0, 0.0, 1500.0)
    cams = []
    for k, target in enumerate([(0, -300, 900), (0, 300, 900), (-300, 0, 1200)]):
        R, t = look_at(centre, target)
        K = np.array([[1100.0, 0, 640], [0, 1100.0, 512], [0, 0, 1]])
        cams.append(Camera(K, np.zeros(5), R, t, (1280, 1024), f"cam{k + 1}"))
    d = wand_dance(Rig(cams), n_frames=200, held_out_frames=10, body_frames=5, radius_mm=700)
    with pytest.raises(CalibrationError, match="share one position"):
        _calibrate(d)


def test_without_a_reference_object_the_root_camera_is_the_world() -> None:
    d = _scene(noise=0.0, frame_samples=1)
    result = wand_calibrate(d.wand, d.wand_length, None, None, (1280, 1024))
    assert result.report["world"].startswith("camera frame of cam")
    root = result.rig[result.rig.names.index(result.report["world"].split()[-1])]
    np.testing.assert_allclose(root.R, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(root.t, 0.0, atol=1e-9)
    # Up to that rigid change of frame the rig is exact: compare relative poses.
    true = {c.name: c for c in d.rig}
    ref = true[root.name]
    for cam in result.rig:
        rel = true[cam.name].R @ ref.R.T
        np.testing.assert_allclose(cam.R, rel, atol=1e-8)
        np.testing.assert_allclose(cam.K, true[cam.name].K, atol=1e-4)


def test_easywand_field_data_fit_at_least_as_well_as_easywand(shared_data) -> None:
    """Three thermal cameras in a cave (SOURCES.md section 2c): easyWand 5.5 reports DLT
    RMSE 0.339, 0.392, 0.415 px with its wand score 0.95; its RMSE definition is not
    stated, so ours is compared as the root mean squared residual length."""
    folder = shared_data / "ushichka_dltdv/2018-07-28_easywand/exported_csv"
    rows = np.genfromtxt(folder / "wandPts.csv", delimiter=",", skip_header=1)[:, 1:]
    wand = rows.reshape(-1, 2, 3, 2).transpose(0, 2, 1, 3) * [1.0, -1.0] + [0.0, 512.0]
    summary = json.loads((folder / "easyWand_summary.json").read_text())
    result = wand_calibrate(wand, 1000 * summary["wandLen_m"], None, None, (640, 512))
    ours = np.array([c["reprojection_rms_px"] for c in result.report["cameras"]]) * np.sqrt(2)
    theirs = np.array(summary["dltRMSE_px"])
    assert np.mean(ours) < np.mean(theirs)  # measured 0.349 vs 0.382 px
    assert np.all(ours < 1.15 * theirs)
    wand_stats = result.report["wand"]
    assert abs(wand_stats["mean_mm"] - 660.0) < 1.0
    assert wand_stats["sd_mm"] < 0.01 * 660.0  # measured 5.2 mm
    for cam in result.rig:  # the cameras' profile: 526 px, strong barrel distortion
        assert abs(cam.K[0, 0] - 526.0) < 20.0
        assert -0.35 < cam.dist[0] < -0.2
