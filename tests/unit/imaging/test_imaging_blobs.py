"""find_blobs: hand-made frames, rendered blobs against their true centres, flags, gates, errors."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from scipy.spatial import cKDTree

from spotlab.geometry import Camera
from spotlab.imaging import (
    FLAG_EDGE,
    FLAG_SATURATED,
    FLAG_TOO_MANY,
    ImagingError,
    find_blobs,
    render_blobs,
)
from spotlab.imaging._components import label_bright


def _grid_centres(rng: np.random.Generator, size: tuple[int, int], step: int) -> np.ndarray:
    gx, gy = np.meshgrid(
        np.arange(step, size[0] - step, step), np.arange(step, size[1] - step, step)
    )
    grid = np.column_stack([gx.ravel(), gy.ravel()]).astype(float)
    return grid + rng.uniform(-0.5, 0.5, grid.shape)


def _rms_error(found: np.ndarray, truth: np.ndarray) -> float:
    dist, _ = cKDTree(found).query(truth)
    return float(np.sqrt(np.mean(dist**2)))


def test_hand_made_blob_weights_value_minus_threshold() -> None:
    img = np.zeros((8, 10), np.uint8)
    img[2:5, 3:6] = [[10, 20, 10], [20, 60, 40], [10, 20, 10]]
    b = find_blobs(img, 5)
    w = np.array([[5, 15, 5], [15, 55, 35], [5, 15, 5]], float)
    assert len(b) == 1
    assert_allclose(b.x, [(w.sum(axis=0) @ [3, 4, 5]) / w.sum()])
    assert_allclose(b.y, [(w.sum(axis=1) @ [2, 3, 4]) / w.sum()])
    assert b.area[0] == 9 and b.peak[0] == 60 and b.flags[0] == 0
    assert_allclose(b.flux, [w.sum()])


def test_centroid_convention_is_the_camera_models() -> None:
    # A point projected by Camera and rendered there is found at the projection.
    K = [[800.0, 0.0, 639.5], [0.0, 800.0, 399.5], [0.0, 0.0, 1.0]]
    cam = Camera(K, None, np.eye(3), [0.0, 0.0, 3000.0], (1280, 800))
    uv = cam.project(np.array([[0.0, 0.0, 0.0], [412.3, -181.7, 0.0]]))
    img = render_blobs(cam.size, uv, 6.0, noise=0.0)
    b = find_blobs(img, 40)
    assert_allclose(b.xy[np.argsort(b.x)], uv[np.argsort(uv[:, 0])], atol=0.05)
    assert_allclose(uv[0], [639.5, 399.5])


@pytest.mark.parametrize("profile", ["disc", "gaussian"])
@pytest.mark.parametrize("diameter", [3.0, 5.0, 10.0])
def test_subpixel_error_on_rendered_blobs(profile: str, diameter: float) -> None:
    rng = np.random.default_rng(int(diameter * 10) + len(profile))
    truth = _grid_centres(rng, (640, 400), 40)
    img = render_blobs((640, 400), truth, diameter, peak=180, profile=profile, noise=2.0, rng=rng)
    b = find_blobs(img, 8 + 0.2 * 180, min_area=2)
    assert len(b) == len(truth)
    assert _rms_error(b.xy, truth) <= 0.05


def test_two_touching_blobs_diagonally_are_one_component() -> None:
    img = np.zeros((6, 6), np.uint16)
    img[1, 1] = 500
    img[2, 2] = 500
    img[4, 4] = 500
    b = find_blobs(img, 100)
    assert_array_equal(b.area, [2, 1])
    assert_allclose(b.xy, [[1.5, 1.5], [4.0, 4.0]])


def test_saturated_and_edge_flags() -> None:
    img = np.zeros((20, 30), np.uint8)
    img[5:8, 5:8] = 255  # saturated
    img[0:2, 14:16] = 100  # touches the top border
    img[12:15, 20:23] = 100  # neither
    b = find_blobs(img, 50)
    by_x = np.argsort(b.x)
    assert_array_equal(b.flags[by_x], [FLAG_SATURATED, FLAG_EDGE, 0])
    assert find_blobs(img, 50, saturation=100).flags[by_x][2] == FLAG_SATURATED


def test_gates_on_area_and_peak() -> None:
    img = np.zeros((30, 30), np.uint8)
    img[2, 2] = 90  # 1 px
    img[10:13, 10:13] = 60  # 9 px, peak 60
    img[20:26, 20:26] = 90  # 36 px
    assert_array_equal(find_blobs(img, 10, min_area=2).area, [9, 36])
    assert_array_equal(find_blobs(img, 10, max_area=10).area, [1, 9])
    assert_array_equal(find_blobs(img, 10, min_peak=80).area, [1, 36])
    assert find_blobs(img, 10, min_area=2).n_components == 3


def test_too_many_keeps_the_brightest_in_raster_order_and_flags_them() -> None:
    rng = np.random.default_rng(3)
    truth = _grid_centres(rng, (400, 300), 20)
    peaks = rng.uniform(60, 200, len(truth))
    img = render_blobs((400, 300), truth, 5.0, peak=peaks, noise=0.0)
    b = find_blobs(img, 30, max_blobs=10)
    assert b.truncated and len(b) == 10 and b.n_components == len(truth)
    assert np.all(b.flags & FLAG_TOO_MANY)
    _, nearest = cKDTree(truth).query(b.xy)
    assert set(nearest) == set(np.argsort(-peaks)[:10])
    first_row = np.floor(b.y - 2)
    assert np.all(np.diff(first_row) >= -1)


def test_a_flooded_frame_returns_flagged_and_empty() -> None:
    img = np.full((100, 100), 200, np.uint8)
    b = find_blobs(img, 50)
    assert b.flooded and len(b) == 0
    assert not find_blobs(img, 50, max_bright=1.0).flooded


def test_dense_frame_labels_like_a_sparse_one() -> None:
    # Above the dense share, the whole-frame labelling gives the same blobs.
    rng = np.random.default_rng(5)
    truth = _grid_centres(rng, (200, 120), 8)
    img = render_blobs((200, 120), truth, 4.0, noise=1.0, rng=rng)
    b = find_blobs(img, 40, max_blobs=1000, max_bright=0.5)
    bright = img > 40
    assert np.count_nonzero(bright) > img.size / 32
    assert len(b) == len(truth)
    assert _rms_error(b.xy, truth) <= 0.05
    index = np.flatnonzero(bright)
    dense, n_dense = label_bright(bright, index)
    graph, n_graph = label_bright(bright, index, dense_fraction=1.0)
    assert n_dense == n_graph == len(truth)
    assert_array_equal(dense, graph)


def test_empty_frame_gives_no_blobs() -> None:
    b = find_blobs(np.zeros((10, 10), np.uint8), 10)
    assert len(b) == 0 and b.xy.shape == (0, 2) and not b.truncated and not b.flooded


@pytest.mark.parametrize(
    ("image", "kwargs", "match"),
    [
        (np.zeros((4, 4, 3), np.uint8), {}, "shape"),
        (np.zeros((4, 4), np.float32), {}, "uint8 or uint16"),
        (np.zeros((4, 4), np.uint8), {"threshold": 255}, "threshold"),
        (np.zeros((4, 4), np.uint8), {"threshold": float("nan")}, "threshold"),
        (np.zeros((4, 4), np.uint8), {"min_area": 0}, "min_area"),
        (np.zeros((4, 4), np.uint8), {"min_area": 5, "max_area": 4}, "max_area"),
        (np.zeros((4, 4), np.uint8), {"max_blobs": 0}, "max_blobs"),
        (np.zeros((4, 4), np.uint8), {"saturation": 5}, "saturation"),
        (np.zeros((4, 4), np.uint8), {"max_bright": 0.0}, "max_bright"),
    ],
)
def test_bad_input_names_the_cause(image: np.ndarray, kwargs: dict, match: str) -> None:
    threshold = kwargs.pop("threshold", 10)
    with pytest.raises(ImagingError, match=match):
        find_blobs(image, threshold, **kwargs)
