"""The simulated body standing still and in a range-of-motion trial (sim centroid --motion
static|rom): the same subject as the walk of the same seed, swaying a few mm when static,
starting in the neutral pose and moving every joint in the ROM trial."""

from __future__ import annotations

import numpy as np
import pytest

from spotlab.console.cli import main
from spotlab.simulators.centroid_body import GaitBody
from spotlab.simulators.centroid_poses import PosedBody, body_for
from spotlab.simulators.centroid_service import CentroidSimOptions


def test_static_is_the_walks_subject_standing_and_swaying_a_few_mm() -> None:
    static, walk = body_for("static", 4), body_for("walk", 4)
    assert isinstance(static, PosedBody) and static.labels == walk.labels
    assert static.subject is not None and walk.subject is not None
    assert static.subject.scale == walk.subject.scale
    X = static.all_markers(np.arange(0.0, 10.0, 0.05))
    sway = np.linalg.norm(X - X.mean(axis=0), axis=2).max()
    assert 2.0 < sway < 25.0  # soft tissue and sway: measured 12.8 mm
    assert X[..., 2].min() > -20.0 and X[..., 2].max() < 2400.0
    assert np.allclose(PosedBody("static", 4).spot, static.spot)  # the seed's spot
    assert not np.allclose(PosedBody("static", 5).spot, static.spot)


def test_rom_starts_in_the_static_pose_then_moves_every_limb() -> None:
    rom, static = PosedBody("rom", 2), PosedBody("static", 2)
    t = np.arange(0.0, 0.9, 0.1)
    assert np.abs(rom.all_markers(t) - static.all_markers(t)).max() < 1e-9
    X = rom.all_markers(np.arange(2.0, 12.0, 0.02))
    trunk = X[:, [rom.labels.index(n) for n in ("LASI", "RASI", "SACR")]].mean(axis=1)
    reach = np.linalg.norm(X - trunk[:, None], axis=2)
    spread = reach.max(axis=0) - reach.min(axis=0)
    # measured: trunk markers 1-5 mm (skin), limbs 39 (thigh) to 289 mm (finger)
    trunk_like = spread < 10.0
    assert trunk_like.sum() == 16  # pelvis, trunk and head move as one
    assert spread[~trunk_like].min() > 30.0
    for name in ("LWRA", "RWRA", "LTOE", "RTOE", "LELB", "RELB"):
        assert spread[rom.labels.index(name)] > 100.0, name


def test_the_motion_option_is_checked() -> None:
    CentroidSimOptions(motion="rom").validate()
    with pytest.raises(ValueError, match="motion 'fly'"):
        CentroidSimOptions(motion="fly").validate()
    with pytest.raises(ValueError, match="motion"):
        PosedBody("walk", 0)
    assert isinstance(body_for("walk", 0), GaitBody)


def test_a_bad_motion_on_the_command_line_is_one_error_line(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert main(["sim", "centroid", "--motion", "fly"]) != 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("spotlab: error:") and "fly" in err[0]
