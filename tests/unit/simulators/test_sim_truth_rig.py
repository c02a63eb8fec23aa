"""The simulated PSD cameras as a spotlab rig (``--rig-out``) and the static ``lframe`` motion."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pytest

from spotlab.console.commands.sim import options_from_args
from spotlab.console.errors import CommandError
from spotlab.geometry import Rig
from spotlab.simulators import wire
from spotlab.simulators.motions import StaticMarkers, make_motion
from spotlab.simulators.psd import PsdModel
from spotlab.simulators.scene import PsdCamera, Scene, ring_rig
from spotlab.simulators.service import SelspotSimOptions, build_device


def _readings(model: PsdModel, cameras: list[PsdCamera], X: np.ndarray) -> np.ndarray:
    """Detector counts (C, N, 2) of static LEDs at ``X`` (N, 3), NaN where not seen,
    saturated (pulled towards the centre) or clipped at the detector's edge (0 or 4094)."""
    scene = Scene(StaticMarkers(X), cameras)
    ids = np.arange(X.shape[0])
    spots = scene.spots(X, np.zeros(ids.size), ids)
    zero = np.zeros((ids.size, len(cameras)))
    r = model.measure(spots, np.full(ids.size, 32.0), zero, zero, np.random.default_rng(0))
    xy = np.stack([r.x, r.y], axis=-1).astype(np.float64)
    bad = ((r.flags & wire.FLAG_VALID) == 0) | ((r.flags & wire.FLAG_SATURATED) != 0)
    bad |= (xy == 0).any(axis=-1) | (xy == 4094).any(axis=-1)
    xy[bad] = np.nan
    return xy.transpose(1, 0, 2)


@pytest.mark.parametrize("pincushion", [0.0, 0.02, 0.05])
def test_rig_reproduces_noise_free_readings_to_the_rounding(pincushion: float) -> None:
    cameras = ring_rig(4, k1=-0.03)
    model = PsdModel(pincushion=pincushion, electrode_noise=0.0)
    rng = np.random.default_rng(1)
    X = rng.uniform([-2000, -2000, 0], [2000, 2000, 2200], size=(3000, 3))
    read = _readings(model, cameras, X)
    rig = model.rig(cameras)
    assert rig.names == ["cam0", "cam1", "cam2", "cam3"]
    assert all(cam.size == (4096, 4096) for cam in rig)
    for cam, psd_cam in zip(rig, cameras, strict=True):
        assert np.allclose(cam.center, psd_cam.center)
    seen = np.isfinite(read[..., 0])
    assert seen.sum() > 5000
    err = np.abs(rig.project(X) - read)[seen]
    # Readings are rounded to whole counts: at most half a count off, about 0.29 RMS.
    assert err.max() <= 0.5 + 1e-3
    assert 0.25 < np.sqrt(np.mean(err**2)) < 0.33
    # The pincushion matters: a rig without it would be many counts off at the edges.
    if pincushion:
        plain = PsdModel(pincushion=0.0).rig(cameras)
        assert np.abs(plain.project(X) - read)[seen].max() > 20.0


def test_rig_refuses_an_off_centre_principal_point_with_a_pincushion() -> None:
    (cam,) = ring_rig(1)
    off = PsdCamera(cam.R, cam.t, principal=(2000.0, 2048.0))
    with pytest.raises(ValueError, match="off the detector centre"):
        PsdModel().rig([off])
    assert PsdModel(pincushion=0.0).rig([off])[0].K[0, 2] == 2000.0


def test_lframe_motion_is_static_and_starts_with_the_l_frame() -> None:
    motion = make_motion("lframe", 6, seed=2)
    assert motion.n_markers == 6
    assert motion.labels[:4] == ("LF_O", "LF_X1", "LF_X2", "LF_Y")
    a, b = motion.positions(0.0), motion.positions(7.3)
    assert np.array_equal(a, b)
    assert np.array_equal(a[:4], [[0, 0, 10], [200, 0, 10], [600, 0, 10], [0, 400, 10]])


def test_build_device_writes_the_true_rig(tmp_path: Path) -> None:
    path = tmp_path / "truth.toml"
    options = SelspotSimOptions(cameras=3, leds=4, motion="lframe", rig_out=path)
    device = build_device(options, now_ns=0)
    rig = Rig.load(path)
    expected = device.psd.rig(device.scene.cameras)
    assert len(rig) == 3
    for got, want in zip(rig, expected, strict=True):
        assert np.allclose(got.K, want.K) and np.allclose(got.dist, want.dist)
        assert np.allclose(got.R, want.R) and np.allclose(got.t, want.t)


def _args(**kw: object) -> argparse.Namespace:
    base: dict[str, object] = dict(
        cameras=2, leds=8, rate=100.0, seed=0, truth=None, fault_log=None, faults="",
        clock_offset=0.0, clock_drift_ppm=0.0, clock_jitter=0.0, motion="wand",
        reflectance=0.05, rig_out=None,
    )  # fmt: skip
    base.update(kw)
    return argparse.Namespace(**base)


def test_command_line_options_reach_the_simulator(tmp_path: Path) -> None:
    options = options_from_args(_args(motion="lframe", reflectance=0.0, rig_out=tmp_path / "r"))
    assert options.motion == "lframe"
    assert options.floor_reflectance == 0.0
    assert options.rig_out == tmp_path / "r"
    with pytest.raises(CommandError, match="--reflectance must be 0 to 1"):
        options_from_args(_args(reflectance=1.5))
    with pytest.raises(CommandError, match="lframe"):
        options_from_args(_args(motion="no-such-motion"))
    with pytest.raises(ValueError, match="floor reflectance"):
        SelspotSimOptions(floor_reflectance=-0.1).validate()
