"""Wand self-calibration of a camera rig from a cold start (Woltring & Huiskes 1990).

``wand_calibrate`` needs no initial guess: the cold start (``_wand_init``) finds every
camera's principal distance, orientation and position from the reference object and the
wand alone; a bundle adjustment (``_wand_bundle``) then estimates all camera parameters
(pose, principal distances, principal point, radial and tangential distortion) and all
wand poses together, with the wand length fixed, the reference object fixing the world
frame, Huber-robust weights and rejection of outlying observations.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from spotlab.calibration._camera_block import BLOCK, cameras_from_blocks
from spotlab.calibration._lens_terms import (
    choose_terms,
    fit_fixed_terms,
    lens_mode,
    next_step,
    term_columns,
)
from spotlab.calibration._rays import intersect
from spotlab.calibration._wand_bundle import (
    BundleProblem,
    BundleState,
    adjust,
    residuals,
    robust_cost,
    robust_sigma,
)
from spotlab.calibration._wand_init import cold_start
from spotlab.calibration.report import image_coverage, lens_report, quality_report
from spotlab.core.errors import CalibrationError
from spotlab.geometry import Camera, Rig
from spotlab.geometry.lens_check import lens_problems

__all__ = ["WandCalibration", "wand_calibrate"]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
Progress = Callable[[str], None]

#: Frames used by the first, coarse adjustment stages.
_COARSE_FRAMES = 1000


@dataclass(frozen=True)
class WandCalibration:
    """Result of :func:`wand_calibrate`.

    Attributes
    ----------
    rig : Rig
        The calibrated cameras, world frame of the reference object, mm.
    report : dict
        Quality figures (see :func:`spotlab.calibration.report.quality_report`) plus the
        run's timings and stages.
    wand_ends : ndarray, shape (F, 2, 3)
        Adjusted wand ends (mm), NaN for frames not used.
    wand_residuals : ndarray, shape (F, C, 2, 2)
        Reprojection residuals (px), NaN where unseen, unused or rejected.
    frame_residuals : ndarray, shape (C, P, 2)
        Residuals of the reference object's markers (px).
    inliers : ndarray of bool, shape (F, C, 2)
        Wand observations kept after outlier rejection.
    """

    rig: Rig
    report: dict[str, Any]
    wand_ends: FloatArray
    wand_residuals: FloatArray
    frame_residuals: FloatArray
    inliers: BoolArray = field(repr=False)


def _sizes(image_size: Any, C: int) -> list[tuple[int, int]]:
    arr = np.asarray(image_size)
    if arr.shape == (2,):
        arr = np.tile(arr, (C, 1))
    if arr.shape != (C, 2) or not np.all(np.isfinite(arr)) or np.any(arr <= 0):
        raise CalibrationError(
            f"image_size must be (width, height) or one per camera ({C}, 2) of positive "
            f"pixels, got {np.asarray(image_size).tolist()!r}"
        )
    return [(int(w), int(h)) for w, h in arr]


def _check(
    wand: Any, wand_length: Any, frame: Any, frame_points: Any
) -> tuple[FloatArray, float, FloatArray, FloatArray]:
    wand = np.asarray(wand, dtype=np.float64)
    if wand.ndim != 4 or wand.shape[2:] != (2, 2):
        raise CalibrationError(
            f"wand must have shape (frames, cameras, 2 ends, 2), got {wand.shape}"
        )
    C = wand.shape[1]
    if C < 2:
        raise CalibrationError(f"a wand calibration needs >= 2 cameras, got {C}")
    if np.any(np.isinf(wand)):
        raise CalibrationError("wand contains infinite image coordinates")
    length = float(wand_length)
    if not np.isfinite(length) or length <= 0:
        raise CalibrationError(f"wand_length must be a positive length in mm, got {wand_length}")
    if (frame is None) != (frame_points is None):
        raise CalibrationError("give both frame and frame_points, or neither")
    if frame is None:
        frame, frame_points = np.full((C, 0, 2), np.nan), np.zeros((0, 3))
    frame = np.asarray(frame, dtype=np.float64)
    frame_points = np.asarray(frame_points, dtype=np.float64)
    if frame_points.ndim != 2 or frame_points.shape[1] != 3:
        raise CalibrationError(f"frame_points must have shape (P, 3), got {frame_points.shape}")
    if not np.all(np.isfinite(frame_points)):
        raise CalibrationError("frame_points contains NaN or infinite coordinates")
    if frame.shape != (C, frame_points.shape[0], 2):
        raise CalibrationError(
            f"frame must have shape (cameras={C}, markers={frame_points.shape[0]}, 2), "
            f"got {frame.shape}"
        )
    if np.any(np.isinf(frame)):
        raise CalibrationError("frame contains infinite image coordinates")
    seen = np.all(np.isfinite(wand), axis=-1)  # (F, C, 2)
    blind = np.flatnonzero(~np.any(seen, axis=(0, 2)))
    if blind.size:
        raise CalibrationError(
            f"camera(s) {', '.join(str(c + 1) for c in blind)} never see the wand"
        )
    pair = np.sum(np.all(seen, axis=2), axis=1) >= 2
    if not np.any(pair):
        raise CalibrationError("no frame in which two cameras see both wand ends")
    if np.count_nonzero(pair) < 20:
        raise CalibrationError(
            f"only {np.count_nonzero(pair)} frames in which two cameras see both wand ends: "
            "at least 20 are needed"
        )
    return wand, length, frame, frame_points


_sigma = robust_sigma


def _retriangulate(
    cameras: Sequence[Camera], wand: FloatArray
) -> tuple[FloatArray, FloatArray, BoolArray]:
    """Wand centres (F, 3), unit directions (F, 3) and usability (F,) from a rig."""
    F = wand.shape[0]
    X, _ = intersect(cameras, wand.transpose(1, 0, 2, 3).reshape(len(cameras), F * 2, 2))
    ends = X.reshape(F, 2, 3)
    d = ends[:, 1] - ends[:, 0]
    with np.errstate(invalid="ignore", divide="ignore"):
        d = d / np.linalg.norm(d, axis=1, keepdims=True)
    usable = np.all(np.isfinite(ends), axis=(1, 2)) & np.all(np.isfinite(d), axis=1)
    return 0.5 * (ends[:, 0] + ends[:, 1]), d, usable


def _frame_weight(wand_res: FloatArray, frame_res: FloatArray) -> float:
    """Relative weight of the reference object's residuals: the ratio of variances.

    The reference object is static, so its image points are means of many samples and
    far less noisy than a moving wand's; each residual set's variance is estimated from
    the adjusted residuals (the reference's 6 pose degrees of freedom deducted), and the
    ratio is kept within [1, 1e4].
    """
    fr = frame_res[np.all(np.isfinite(frame_res), axis=-1)]
    n = fr.size
    if n <= 12:
        return 1.0
    var_f = float(np.sum(fr * fr)) / (n - 6)
    var_w = float(np.mean(wand_res * wand_res))
    return float(np.clip(var_w / max(var_f, 1e-300), 1.0, 1e4))


def _free_mask(
    C: int,
    stage: str,
    terms: Sequence[Sequence[str]],
    principal_point: bool,
    fixed: int | None,
) -> BoolArray:
    """Adjusted parameters per camera; ``fixed`` camera keeps its pose (gauge).

    ``terms[c]`` are the distortion terms adjusted for camera ``c`` in the full stage.
    """
    free = np.zeros((C, BLOCK), dtype=bool)
    free[:, 0:8] = True  # rotation, translation, fx, fy
    if fixed is not None:
        free[fixed, 0:6] = False
    if stage == "full":
        if principal_point:
            free[:, 8:10] = True
        for c in range(C):
            free[c, term_columns(terms[c])] = True
    return free


def _final_stages(
    wand: FloatArray,
    length: float,
    frame: FloatArray,
    frame_points: FloatArray,
    state: BundleState,
    free: BoolArray,
    sizes: list[tuple[int, int]],
    names: list[str],
    outlier_sigma: float,
    say: Progress,
) -> tuple[BundleState, BundleProblem, NDArray[np.intp], list[dict[str, Any]]]:
    """Re-triangulate every frame with the current rig, adjust, reject outliers, adjust."""
    cameras = cameras_from_blocks(state.blocks, state.rotations, sizes, names)
    centres, directions, ok = _retriangulate(cameras, wand)
    frames = np.flatnonzero(ok)
    state = BundleState(state.blocks, state.rotations, centres[frames], directions[frames])
    problem = BundleProblem(wand[frames], length, frame, frame_points, free)
    stages: list[dict[str, Any]] = []
    for stage in ("all frames", "outliers rejected"):
        r, fr = residuals(problem, state)
        sigma = _sigma(r)
        if stage == "outliers rejected":
            problem.use &= ~(np.linalg.norm(r, axis=-1) > outlier_sigma * sigma)
            problem.frame_weight = _frame_weight(r[problem.use], fr)
        problem.huber_px = max(3.0 * sigma, 1e-3)
        say(f"adjusting {frames.size} frames: {stage}")
        state, log = adjust(problem, state, max_iterations=50)
        stages.append({"stage": stage, "frames": int(frames.size), **vars(log)})
    return state, problem, frames, stages


def wand_calibrate(
    wand: Any,
    wand_length: float,
    frame: Any,
    frame_points: Any,
    image_size: Any,
    *,
    names: Sequence[str] | None = None,
    distortion: str | Sequence[str] = "auto",
    principal_point: bool = True,
    outlier_sigma: float = 5.0,
    units: str = "px",
    progress: Progress | None = None,
) -> WandCalibration:
    """Calibrate a rig from a wand dance and a static reference object, no guess needed.

    Parameters
    ----------
    wand : array_like, shape (F, C, 2, 2)
        Image points (px) of both wand ends per frame and camera, NaN where unseen.
    wand_length : float
        Distance between the wand's two markers (mm).
    frame : array_like, shape (C, P, 2), or None
        Image points (px) of the static reference object (L-frame or triad), averaged
        over its static recording, NaN where unseen. ``None`` (with ``frame_points``
        None) when there is none: the world frame is then the camera frame of the
        camera that shares most wand frames with the others (``report["world"]``).
    frame_points : array_like, shape (P, 3), or None
        The reference object's marker coordinates (mm), which define the world frame.
    image_size : (width, height) or array_like, shape (C, 2)
        Image size (px) of all cameras or of each.
    names : sequence of str, optional
        Camera names (default ``cam1`` ... ``camC``).
    distortion : str or sequence of str
        Lens terms estimated. ``"auto"`` (default): per camera the richest of
        ``(), (k1,), (k1, k2), (k1, k2, p1, p2), (k1, k2, p1, p2, k3)`` that the
        wand's image coverage and the normal matrix determine (``_lens_terms``), one
        step less for a camera whose fitted model would not invert over its whole image.
        ``"none"``, ``"radial"`` (k1, k2), ``"full"`` (all five) or a subset of
        ``("k1", "k2", "p1", "p2", "k3")``: those terms for every camera. The others
        stay zero. ``report["cameras"][c]["distortion"]`` says what was fitted and why.
    principal_point : bool
        Estimate the principal point (otherwise it stays at the image centre).
    outlier_sigma : float
        Observations whose residual exceeds this many robust standard deviations are
        rejected before the final adjustment.
    units : str
        Name of the image unit, for the report (``"px"``; ``"counts"`` for a PSD).
    progress : callable, optional
        Called with a short message at each stage.

    Returns
    -------
    WandCalibration
        ``.rig`` and ``.report`` (see :func:`spotlab.calibration.report.quality_report`).

    Raises
    ------
    CalibrationError
        Naming the cause: bad shapes, NaN in the reference coordinates, a camera that
        never sees the wand, too few frames seen by two cameras, cameras that share one
        position, a reference object not seen by two cameras, no convergence, or (for a
        fixed set of terms) a fitted lens model that does not invert over its image
        (``spotlab.geometry.lens_check``).
    """
    t0 = time.perf_counter()
    say = progress or (lambda _msg: None)
    wand, length, frame, frame_points = _check(wand, wand_length, frame, frame_points)
    F, C = wand.shape[:2]
    sizes = _sizes(image_size, C)
    names = list(names) if names is not None else [f"cam{c + 1}" for c in range(C)]
    if len(names) != C:
        raise CalibrationError(f"{len(names)} names given for {C} cameras")
    mode, fixed_terms = lens_mode(distortion)

    say("cold start: principal distances, relative orientations, world frame")
    init = cold_start(wand, length, frame, frame_points, sizes)
    # Without a reference object the root camera's pose fixes the world frame.
    gauge = None if frame_points.shape[0] else init.root
    blocks = np.zeros((C, BLOCK))
    blocks[:, 3:6] = init.translations
    blocks[:, 6] = blocks[:, 7] = init.focal
    blocks[:, 8:10] = init.principal_point
    usable = np.flatnonzero(init.usable)
    if usable.size < 20:
        raise CalibrationError(
            f"only {usable.size} wand frames could be triangulated from the initial rig"
        )
    timings = {"cold_start_s": time.perf_counter() - t0}

    coarse = usable[np.linspace(0, usable.size - 1, min(_COARSE_FRAMES, usable.size)).astype(int)]
    state = BundleState(
        blocks, init.rotations.copy(), init.centres[coarse], init.directions[coarse]
    )
    coverage = [image_coverage(wand[:, c].reshape(-1, 2), sizes[c]) for c in range(C)]
    base = _free_mask(C, "full", [()] * C, principal_point, gauge)
    stages: list[dict[str, Any]] = []
    say(f"adjusting {coarse.size} frames: pose+focal")
    problem = BundleProblem(
        wand[coarse], length, frame, frame_points, _free_mask(C, "", [], False, gauge)
    )
    problem.huber_px = max(3.0 * _sigma(residuals(problem, state)[0]), 0.1)
    state, log = adjust(problem, state, max_iterations=40)
    stages.append({"stage": "pose+focal", "frames": int(coarse.size), **vars(log)})
    say(f"adjusting {coarse.size} frames: full, lens terms ({mode})")
    problem.huber_px = max(3.0 * _sigma(residuals(problem, state)[0]), 0.1)
    cost = robust_cost(problem, state)
    if mode == "auto":
        choices, state = choose_terms(problem, state, base, sizes, coverage)
    else:
        choices, state = fit_fixed_terms(mode, fixed_terms, problem, state, base, sizes)
    terms = [ch.terms for ch in choices]
    stages.append(
        {
            "stage": "full",
            "frames": int(coarse.size),
            "initial_cost": cost,
            "final_cost": robust_cost(problem, state),
        }
    )
    coarse_problem = problem
    fitted = [f"{n} {', '.join(t) or 'none'}" for n, t in zip(names, terms, strict=True)]
    say("lens terms: " + "; ".join(fitted))

    tried: list[set[tuple[str, ...]]] = [set() for _ in range(C)]
    while True:
        # The stage-2 lens must invert before every wand point is triangulated through
        # it; the final one before it is returned.
        cameras = cameras_from_blocks(state.blocks, state.rotations, sizes, names)
        problems = [lens_problems(cam) for cam in cameras]
        if not any(problems):
            free = _free_mask(C, "full", terms, principal_point, gauge)
            final, problem, frames, more = _final_stages(
                wand, length, frame, frame_points, state, free, sizes, names, outlier_sigma, say
            )
            stages += more
            cameras = cameras_from_blocks(final.blocks, final.rotations, sizes, names)
            problems = [lens_problems(cam) for cam in cameras]
            if not any(problems):
                state = final
                break
        if mode != "auto":
            c = next(i for i, p in enumerate(problems) if p)
            raise CalibrationError(
                f"{names[c]}: the fitted lens model ({', '.join(terms[c])}) cannot be "
                f"inverted over the whole image: {problems[c][0]}; "
                "fit fewer terms (distortion 'auto' or 'none') or cover more of the image"
            )
        for c, found in enumerate(problems):
            if not found:
                continue
            tried[c].add(terms[c])
            step = next_step(choices[c], found, tried[c], coverage[c])
            if step is None:
                raise CalibrationError(
                    f"{names[c]}: no lens model fitted from this wand dance can be inverted "
                    f"over the whole image ({found[0]}); cover more of the image"
                )
            choices[c], terms[c] = step, step.terms
            keep = term_columns(terms[c])
            for col in range(10, 15):
                if col not in keep:
                    state.blocks[c, col] = 0.0
            say(f"{names[c]}: lens model does not invert over the image; trying {step.reason}")
        # Adjust the new terms on the stage-2 frames (projection only: no inversion
        # needed) before the wand is triangulated through them again.
        coarse_problem.free = _free_mask(C, "full", terms, principal_point, gauge)
        state, _ = adjust(coarse_problem, state, max_iterations=40)
    timings["total_s"] = time.perf_counter() - t0

    cameras = cameras_from_blocks(state.blocks, state.rotations, sizes, names)
    rig = Rig(cameras)
    r_wand, r_frame = residuals(problem, state)
    wand_res = np.full((F, C, 2, 2), np.nan)
    wand_res[frames] = r_wand
    inliers = np.zeros((F, C, 2), dtype=bool)
    inliers[frames] = problem.use
    ends = np.full((F, 2, 3), np.nan)
    ends[frames] = state.wand_ends(length)
    report = quality_report(rig, wand, length, wand_res, r_frame, inliers, units)
    lens_report(report, mode, choices)
    report["stages"] = stages
    report["timings"] = timings
    report["cold_start_tree"] = [[p + 1, q + 1] for p, q in init.tree]
    report["world"] = "reference object" if gauge is None else f"camera frame of {names[init.root]}"
    return WandCalibration(
        rig=rig,
        report=report,
        wand_ends=ends,
        wand_residuals=wand_res,
        frame_residuals=r_frame,
        inliers=inliers,
    )
