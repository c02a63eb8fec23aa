"""Every wrong input to triangulate raises ReconstructionError naming its cause."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from spotlab.core.errors import ReconstructionError
from spotlab.geometry import Camera, Rig
from spotlab.reconstruction import triangulate
from spotlab.simulators.rigs import ring_rig

RIG = ring_rig(4)
UV = RIG.project(np.array([[0.0, 0.0, 900.0], [100.0, 200.0, 1200.0]]))


@pytest.mark.parametrize(
    ("rig", "uv", "kwargs", "match"),
    [
        (list(RIG), UV, {}, "rig must be a spotlab Rig"),
        (RIG, UV[..., :1], {}, r"shape \(C, ..., 2\)"),
        (RIG, UV[0, 0], {}, r"shape \(C, ..., 2\)"),
        (RIG, UV[:3], {}, "observations of 3 cameras but the rig has 4"),
        (RIG, np.where(UV > 500, np.inf, UV), {}, "infinite"),
        (RIG, [["a", "b"]], {}, "numeric"),
        (RIG, UV, {"method": "svd"}, "unknown triangulation method 'svd'"),
        (RIG, UV, {"iterations": -1}, "iterations must be >= 0"),
        (RIG, UV, {"refine": -2}, "refine must be >= 0"),
        (RIG, UV, {"weights": np.ones(3)}, "do not broadcast"),
        (RIG, UV, {"weights": -np.ones((4, 1))}, "finite and >= 0"),
        (RIG, UV, {"weights": [[1.0], [np.nan], [1.0], [1.0]]}, "finite and >= 0"),
        (RIG, UV, {"method": "midpoint"}, "exactly two views"),
        (RIG, UV, {"workers": 0}, "workers must be an integer >= 1"),
        (RIG, UV, {"workers": 1.5}, "workers must be an integer >= 1"),
    ],
)
def test_bad_input(rig: Any, uv: Any, kwargs: dict[str, Any], match: str) -> None:
    with pytest.raises(ReconstructionError, match=match):
        triangulate(rig, uv, **kwargs)


def test_strict_names_the_points_without_two_views() -> None:
    uv = UV.copy()
    uv[1:, 1] = np.nan
    assert np.isnan(triangulate(RIG, uv)[1]).all()
    with pytest.raises(ReconstructionError, match="1 of 2 points are seen by fewer than two"):
        triangulate(RIG, uv, strict=True)


def test_pixel_beyond_the_distortion_fold() -> None:
    cam = RIG[0]
    strong = Camera(cam.K, [-0.6, 0.0, 0.0, 0.0, 0.0], cam.R, cam.t, cam.size, "strong")
    rig = Rig([strong, RIG[1]])
    uv = np.array([[[5000.0, 5000.0]], [[600.0, 500.0]]])  # far outside the fold radius
    with pytest.raises(ReconstructionError, match="camera 'strong'"):
        triangulate(rig, uv)


def test_empty_input_gives_empty_output() -> None:
    assert triangulate(RIG, np.zeros((4, 0, 2))).shape == (0, 3)
