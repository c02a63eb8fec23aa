"""The wand and the L-frame found among a video camera's blobs (ghosts, noise, missing and
merged markers), with blobs rendered by the centroid simulator's camera model."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.typing import NDArray

from spotlab.calibration.frame_finder import AMBIGUOUS, FOUND, NOT_FOUND, find_frame
from spotlab.calibration.wand_finder import find_wand, middle_places, survey_wand
from spotlab.calibration.wand_relabel import relabel_two_ends
from spotlab.core.errors import CalibrationError
from spotlab.geometry import Camera, Rig
from spotlab.simulators.blobs import MERGED, BlobModel, render_camera
from spotlab.simulators.motions import WandDance, reference_markers
from spotlab.simulators.rigs import ring_rig

FloatArray = NDArray[np.float64]
RIG = ring_rig(8)
WAND = WandDance(500.0, (0.0, 0.0, 1000.0), 1200.0, 200.0, 650.0, seed=3, middle_mm=200.0)
L_FRAME = reference_markers(4).points
PEAKS: list[float] = []


def _positions(motion: WandDance, times: FloatArray) -> FloatArray:
    m = motion.n_markers
    X = motion.sample(np.repeat(times, m), np.tile(np.arange(m), times.size))
    return np.asarray(X.reshape(times.size, m, 3))


def _render(
    cam: Camera, X: FloatArray, model: BlobModel, seed: int = 0, **kw: object
) -> tuple[FloatArray, NDArray[np.int64], NDArray[np.bool_], list[NDArray[np.int64]]]:
    """Blobs of frames X (F, M, 3) in one camera: flat uv, offsets, usable mask, markers
    (peaks in ``PEAKS``)."""
    rng = np.random.default_rng(seed)
    uv, counts, usable, marker = [], [], [], []
    PEAKS.clear()
    for x in X:
        b = render_camera(cam, x, model, rng, **kw)  # type: ignore[arg-type]
        PEAKS.extend(b.peak)
        uv.append(b.uv)
        counts.append(b.uv.shape[0])
        usable.append((b.flags & MERGED) == 0)
        marker.append(np.where(b.kind == 0, b.marker, -1))
    offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    return np.concatenate(uv), offsets, np.concatenate(usable), marker


def test_middle_places_orders_the_ends_by_the_middle_marker() -> None:
    uv = np.array([[[100.0, 0.0], [0.0, 0.0], [40.0, 0.5]]])
    a, b, m, place, off = middle_places(uv)
    np.testing.assert_allclose(a[0], [0, 0])  # the end nearer the middle
    np.testing.assert_allclose(b[0], [100, 0])
    np.testing.assert_allclose(m[0], [40, 0.5])
    assert place[0] == pytest.approx(0.4) and off[0] == pytest.approx(0.5)


def test_three_marker_wand_among_ghosts_and_noise_is_never_wrong() -> None:
    cam = RIG.cameras[0]
    X = _positions(WAND, np.arange(400) / 50.0)
    model = BlobModel(noise_blobs=2.0)  # 100 times the simulator's default
    ghosts = np.array([False, True, False])  # the camera sees end B's floor reflection
    uv, offsets, usable, marker = _render(cam, X, model, ghosts=ghosts)
    found = find_wand(uv, offsets, 1, markers=3, middle_ratio=0.4, usable_blob=usable)
    F = X.shape[0]
    assert found.used[0] + found.ambiguous[0] + found.missing[0] + found.unusable[0] == F
    truth = cam.project(X.reshape(-1, 3)).reshape(F, 3, 2)
    used = np.isfinite(found.ends[:, 0, 0, 0])
    err = np.linalg.norm(found.ends[used, 0] - truth[used, :2], axis=-1)
    err_m = np.linalg.norm(found.middle[used, 0] - truth[used, 2], axis=-1)
    assert max(err.max(), err_m.max()) < 0.5  # end A, end B and the middle: right ones
    # Images where all three markers have their own blob: most of them are used (measured
    # 95 %; the others hold a second triple of noise blobs that fits, and are dropped).
    whole = np.array([np.isin([0, 1, 2], mk).all() for mk in marker])
    assert used[whole].mean() > 0.9, (found.used, found.ambiguous, found.missing)
    assert not used[~whole].any()  # a hidden or merged marker: never a guess
    print(f"used {found.used}, ambiguous {found.ambiguous}, missing {found.missing}")


def test_hidden_and_merged_markers_drop_the_image() -> None:
    cam = RIG.cameras[2]
    X = _positions(WAND, np.arange(60) / 50.0)
    hidden = np.array([False, False, True])  # the middle marker is occluded
    uv, offsets, usable, _ = _render(cam, X, BlobModel(noise_blobs=0.0), hidden=hidden)
    found = find_wand(uv, offsets, 1, markers=3, middle_ratio=0.4, usable_blob=usable)
    assert found.used[0] == 0 and found.missing[0] == 60
    # The middle marker merged with end A: two blobs, one flagged; then unflagged merges.
    uv = np.array([[100.0, 100.0], [101.0, 100.5], [300.0, 200.0]])
    merged = np.array([True, False, True])  # blob 0 is a merge (flagged)
    for mask in (merged, None):
        pts = uv[[0, 2]] if mask is None else uv
        offs = np.array([0, pts.shape[0]])
        usable_blob = None if mask is None else ~mask
        found = find_wand(pts, offs, 1, markers=3, middle_ratio=0.4, usable_blob=usable_blob)
        assert found.missing[0] == 1 and found.used[0] == 0


def test_a_mirrored_wand_is_told_apart_by_its_brightness_or_dropped() -> None:
    """A whole floor reflection of the wand is a second wand: dimmer, or dropped."""
    cam = RIG.cameras[1]
    X = _positions(WAND, np.arange(200) / 50.0)
    model = BlobModel(noise_blobs=0.0)
    uv, offsets, usable, _ = _render(cam, X, model, ghosts=np.ones(3, dtype=bool))
    blind = find_wand(uv, offsets, 1, markers=3, middle_ratio=0.4, usable_blob=usable)
    peak = np.array(PEAKS)
    found = find_wand(uv, offsets, 1, markers=3, middle_ratio=0.4, usable_blob=usable, peak=peak)
    print(f"without peaks used {blind.used}, ambiguous {blind.ambiguous}; with {found.used}")
    assert blind.ambiguous[0] > 100  # both wands in view fit
    assert found.used[0] > blind.used[0] + 100
    truth = cam.project(X.reshape(-1, 3)).reshape(-1, 3, 2)
    used = np.isfinite(found.ends[:, 0, 0, 0])
    wrong = np.linalg.norm(found.ends[used, 0] - truth[used, :2], axis=-1).max(axis=1) > 0.5
    # Known defect: with the operator's dance low over the floor, the real wand's triple
    # sometimes fails the line and ratio tests (a marker merged or off by perspective)
    # while its reflection's passes alone, and the reflection is taken: measured 13 of
    # 193 used images in this camera. The bundle adjustment rejects such an image as an
    # outlier (the other cameras disagree); the finder should test it in 3-D.
    print(f"reflection taken in {wrong.sum()} of {used.sum()} used images")
    assert wrong.mean() <= 0.08


def test_the_wrong_middle_ratio_finds_nothing_and_the_survey_tells_the_ratio() -> None:
    cam = RIG.cameras[4]
    X = _positions(WAND, np.arange(300) / 50.0)
    uv, offsets, usable, _ = _render(cam, X, BlobModel(noise_blobs=0.0))
    wrong = find_wand(uv, offsets, 1, markers=3, middle_ratio=0.25, usable_blob=usable)
    assert wrong.used[0] < 0.05 * X.shape[0]
    survey = survey_wand(uv, offsets, 1, usable_blob=usable)
    assert survey.three_in_line > 0.9 * X.shape[0] and survey.two < 0.05 * X.shape[0]
    assert survey.ratio_seen == pytest.approx(0.4, abs=0.015)  # perspective: measured 0.389


def test_two_marker_wand_upper_end_first_and_level_images_dropped() -> None:
    uv = np.array(
        [[10.0, 300.0], [40.0, 100.0],  # steep: end A is the upper one (smaller v)
         [10.0, 100.0], [200.0, 130.0],  # nearly level: dropped
         [0.0, 0.0], [50.0, 90.0], [300.0, 300.0]]  # three blobs: ambiguous
    )  # fmt: skip
    offsets = np.array([0, 2, 4, 7])
    found = find_wand(uv, offsets, 1, markers=2)
    np.testing.assert_allclose(found.ends[0, 0], [[40, 100], [10, 300]])
    assert np.isnan(found.ends[1:]).all()
    assert (found.used[0], found.ambiguous[0], found.missing[0]) == (1, 2, 0)


def test_bad_arguments_are_calibration_errors() -> None:
    uv, offsets = np.zeros((3, 2)), np.array([0, 3])
    with pytest.raises(CalibrationError, match="2 or 3 markers"):
        find_wand(uv, offsets, 1, markers=4)
    with pytest.raises(CalibrationError, match="off the centre"):
        find_wand(uv, offsets, 1, markers=3, middle_ratio=0.48)
    with pytest.raises(CalibrationError, match="do not fit"):
        find_wand(uv, np.array([0, 2]), 1, markers=2)


def _static(
    points: FloatArray, frames: int = 40, *, ghosts: bool = False, noise: float = 0.5
) -> tuple[FloatArray, NDArray[np.int64], NDArray[np.bool_]]:
    """Blobs of a static object in all 8 cameras, frames x cameras, row-major (peaks in
    ``PEAKS``)."""
    rng = np.random.default_rng(5)
    model = BlobModel(noise_blobs=noise)
    uv, counts, usable = [], [], []
    PEAKS.clear()
    for _ in range(frames):
        for cam in RIG.cameras:
            b = render_camera(
                cam, points, model, rng, ghosts=np.full(len(points), ghosts, dtype=bool)
            )
            uv.append(b.uv)
            PEAKS.extend(b.peak)
            counts.append(b.uv.shape[0])
            usable.append((b.flags & MERGED) == 0)
    offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    return np.concatenate(uv), offsets, np.concatenate(usable)


def test_the_l_frame_is_found_in_every_camera_and_averaged() -> None:
    uv, offsets, usable = _static(L_FRAME)
    found = find_frame(uv, offsets, 8, L_FRAME, usable_blob=usable)
    assert found.status == [FOUND] * 8, (found.status, found.fits)
    err = np.linalg.norm(found.uv - RIG.project(L_FRAME), axis=-1)
    assert err.max() < 0.05, err  # 0.07 px noise averaged over 40 images
    assert (found.images == 40).all() and (found.static_blobs == 4).all()


def test_floor_reflections_of_the_l_frame_are_never_taken_for_it() -> None:
    """Every marker's reflection in view: a second, dimmer L-frame 20 mm below."""
    uv, offsets, usable = _static(L_FRAME, ghosts=True)
    blind = find_frame(uv, offsets, 8, L_FRAME, usable_blob=usable)
    assert blind.status == [AMBIGUOUS] * 8, blind.status
    found = find_frame(uv, offsets, 8, L_FRAME, usable_blob=usable, peak=np.array(PEAKS))
    assert found.status == [FOUND] * 8, found.status
    err = np.linalg.norm(found.uv - RIG.project(L_FRAME), axis=-1)
    assert err.max() < 0.05


def test_a_moving_object_or_a_symmetric_one_is_not_found() -> None:
    frames = 30
    uv, offsets, usable = _static(L_FRAME, frames)
    # Every image shifted by its own amount: nothing stays put.
    shift = np.repeat(np.arange(frames * 8) * 7.0 % 200, np.diff(offsets))
    moving = find_frame(uv + shift[:, None], offsets, 8, L_FRAME, usable_blob=usable)
    assert moving.status == [NOT_FOUND] * 8
    square = np.array([[0.0, 0, 10], [400, 0, 10], [400, 400, 10], [0, 400, 10]])
    uv, offsets, usable = _static(square, 10)
    found = find_frame(uv, offsets, 8, square, usable_blob=usable)
    assert FOUND not in found.status  # no collinear triple: 4 rotations fit


def test_two_marker_ends_are_named_again_by_a_first_calibration() -> None:
    """Level images and a ghost beside the wand: named by projecting the wand's ends."""
    wand = WandDance(500.0, (0.0, 0.0, 1100.0), 1000.0, 500.0, 900.0, seed=2)
    X = _positions(wand, np.arange(300) / 50.0)  # (F, 2, 3)
    cams = RIG.cameras[:3]
    rng = np.random.default_rng(2)
    model = BlobModel(noise_blobs=0.5)
    uv, counts, usable = [], [], []
    for x in X:
        for c, cam in enumerate(cams):
            b = render_camera(cam, x, model, rng, ghosts=np.array([c == 1, False]))
            uv.append(b.uv)
            counts.append(b.uv.shape[0])
            usable.append((b.flags & MERGED) == 0)
    offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    flat, ok = np.concatenate(uv), np.concatenate(usable)
    first = find_wand(flat, offsets, 3, markers=2, usable_blob=ok)
    rig = Rig(list(cams))
    named = relabel_two_ends(flat, offsets, rig, X, usable_blob=ok)
    truth = rig.project(X.reshape(-1, 3)).reshape(3, -1, 2, 2).transpose(1, 0, 2, 3)
    used = np.isfinite(named.ends[..., 0, 0])
    assert np.linalg.norm(named.ends[used] - truth[used], axis=-1).max() < 0.5  # never swapped
    assert (named.used > first.used + 30).all(), (named.used, first.used)
    assert (named.used > 0.9 * X.shape[0]).all(), named.used
    # The first naming (upper end first) is not the same physical end in every camera.
    is_b = np.linalg.norm(first.ends[..., 0, :] - truth[..., 1, :], axis=-1) < 1.0  # (F, C)
    seen = np.isfinite(first.ends[..., 0, 0])
    mixed = [len(set(is_b[f][seen[f]].tolist())) > 1 for f in range(X.shape[0])]
    print(f"first naming: {first.used} used, {sum(mixed)} frames with ends swapped between")
    print(f"cameras; named again: {named.used} used")
