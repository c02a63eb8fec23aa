"""SMAC: several cameras calibrated together from a planar grid at unknown attitudes.

Simultaneous Multiframe Analytical Calibration (Woltring 1980): a known planar grid is
held at several attitudes in the volume seen by >= 2 convergent cameras; all camera
parameters (intrinsics, distortion, pose) and all grid poses but one are unknowns; the
one fixed grid pose defines the world frame.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from spotlab.calibration._bundle import CAMERA_PARAMS, BundleState, adjust
from spotlab.calibration.planar import (
    PlanarCalibration,
    calibrate_intrinsics,
    camera_mask,
    check_determined,
    check_grid,
    image_size_checked,
    usable_views,
    view_points,
)
from spotlab.core.errors import CalibrationError
from spotlab.geometry import Camera, Rig

__all__ = ["SmacCalibration", "smac_calibrate"]

FloatArray = NDArray[np.float64]

#: Fewest usable grid views per camera for its own initial (Zhang) calibration.
MIN_VIEWS = 3


@dataclass(frozen=True)
class SmacCalibration:
    """Outcome of :func:`smac_calibrate`.

    Attributes
    ----------
    rig : Rig
        The calibrated cameras, in the world frame of the reference grid pose.
    grid_poses : ndarray, shape (V, 4, 4)
        Grid-to-world rigid transforms ``X = T[:3, :3] P + T[:3, 3]`` per view; the
        reference view's is the identity; NaN for views that could not be used.
    rms_px : ndarray, shape (C,)
        Root mean square of the residual distances per camera (px).
    residuals : ndarray, shape (C, V, P, 2)
        Observed minus modelled image coordinates (px), NaN where not observed or the
        view was not used.
    report : dict
        ``reference_view``, ``unused_views``, ``views_per_camera``,
        ``observations_per_camera``, ``rms_px`` and ``initial_rms_px`` per camera (the
        latter from each camera's own Zhang calibration), ``std`` (standard errors of the
        estimated camera parameters, per camera), ``iterations``.
    """

    rig: Rig
    grid_poses: FloatArray
    rms_px: FloatArray
    residuals: FloatArray
    report: dict[str, Any]


def _robust_pose(Rs: list[FloatArray], ts: list[FloatArray]) -> tuple[FloatArray, FloatArray]:
    """Element-wise median of rotations projected back onto SO(3), median translation."""
    u, _, vt = np.linalg.svd(np.median(np.array(Rs), axis=0))
    R = u @ np.diag([1.0, 1.0, np.linalg.det(u @ vt)]) @ vt
    return R, np.median(np.array(ts), axis=0)


def _chain_poses(
    per_camera: list[dict[int, tuple[FloatArray, FloatArray]]],
    reference: int,
    names: list[str],
) -> tuple[list[tuple[FloatArray, FloatArray]], dict[int, tuple[FloatArray, FloatArray]]]:
    """World-to-camera poses and grid-to-world poses linked through shared views.

    ``per_camera[c][v] = (R, t)`` is the grid-to-camera pose of view ``v`` in camera
    ``c``. The grid at ``reference`` is the world frame.
    """
    views: dict[int, tuple[FloatArray, FloatArray]] = {reference: (np.eye(3), np.zeros(3))}
    cams: dict[int, tuple[FloatArray, FloatArray]] = {}
    changed = True
    while changed:
        changed = False
        for c, seen in enumerate(per_camera):
            shared = [v for v in seen if v in views]
            if c in cams or not shared:
                continue
            # world -> camera = (grid -> camera) o (grid -> world)^-1
            Rs = [seen[v][0] @ views[v][0].T for v in shared]
            ts = [seen[v][1] - R @ views[v][1] for v, R in zip(shared, Rs, strict=True)]
            cams[c] = _robust_pose(Rs, ts)
            changed = True
        for v in sorted({v for seen in per_camera for v in seen} - set(views)):
            known = [c for c in cams if v in per_camera[c]]
            if not known:
                continue
            # grid -> world = (world -> camera)^-1 o (grid -> camera)
            Rs = [cams[c][0].T @ per_camera[c][v][0] for c in known]
            ts = [cams[c][0].T @ (per_camera[c][v][1] - cams[c][1]) for c in known]
            views[v] = _robust_pose(Rs, ts)
            changed = True
    lost = [names[c] for c in range(len(per_camera)) if c not in cams]
    if lost:
        raise CalibrationError(
            f"cameras {lost} share no grid view with the cameras that see the reference "
            "view (directly or through other cameras): their pose cannot be linked"
        )
    return [cams[c] for c in range(len(per_camera))], views


def _sizes(image_size: Any, n_cam: int) -> list[tuple[int, int]]:
    arr = np.asarray(image_size)
    if arr.shape == (2,):
        arr = np.broadcast_to(arr, (n_cam, 2))
    if arr.shape != (n_cam, 2):
        raise CalibrationError(
            f"image_size must be (width, height) or one per camera ({n_cam}, 2), got {arr.shape}"
        )
    return [image_size_checked(row) for row in arr]


def smac_calibrate(
    grid_points: Any,
    image_points: Any,
    image_size: Any,
    *,
    reference_view: int = 0,
    distortion: bool | Sequence[str] = ("k1", "k2"),
    skew: bool = False,
    names: Sequence[str] | None = None,
    max_iter: int = 100,
) -> SmacCalibration:
    """Calibrate a rig from a planar grid held at several unknown attitudes (SMAC).

    Parameters
    ----------
    grid_points : array_like, shape (P, 2) or (P, 3)
        The grid points in the grid's own frame (mm, Z = 0).
    image_points : array_like, shape (C, V, P, 2)
        Image coordinates (px) of every grid point in every view and camera; NaN where
        a camera does not see a point.
    image_size : (int, int) or array_like, shape (C, 2)
        ``(width, height)`` (px), shared or per camera.
    reference_view : int
        The view whose grid pose defines the world frame (origin and axes of the grid,
        ``Z`` normal to it).
    distortion : bool or sequence of str
        Distortion terms to estimate per camera, of ``k1, k2, p1, p2, k3``.
    skew : bool
        Estimate the shear ``K[0, 1]`` of each camera too.
    names : sequence of str, optional
        Camera names; ``cam1`` ... by default.
    max_iter : int
        Levenberg-Marquardt steps allowed in the joint adjustment.

    Returns
    -------
    SmacCalibration
        ``rig``, ``grid_poses`` (V, 4, 4), ``rms_px`` (C,), ``residuals`` and ``report``.

    Raises
    ------
    CalibrationError
        Fewer than 2 cameras, a camera with fewer than 3 usable views (>= 4 observed,
        non-collinear points), a camera whose own Zhang calibration fails (grid planes
        all parallel, ...), cameras that share no view, a reference view no camera can
        use, an invalid grid, infinite coordinates.

    Notes
    -----
    Initialisation: each camera is calibrated on its own from the views it sees
    (:func:`calibrate_intrinsics`), which gives its intrinsics and the grid-to-camera
    pose ``(R_cv, t_cv)`` of each view. Camera poses follow from the views they share
    with already placed ones, ``R_c = R_cv R_v'``, ``t_c = t_cv - R_c t_v``, and grid
    poses from placed cameras, ``R_v = R_c' R_cv``, ``t_v = R_c' (t_cv - t_c)``,
    starting from the reference view (``R = I, t = 0``); where several estimates exist
    the element-wise median is taken (the rotation projected back onto SO(3)). Then
    one bundle adjustment over all camera parameters and all grid poses but the
    reference minimises the image residuals ``u_cvp - project_c(R_v P_p + t_v)``
    (Levenberg-Marquardt, pose blocks eliminated by Schur complement). References:
    H. J. Woltring, "Planar control in multi-camera calibration for three-dimensional
    gait studies", J Biomech 13(1):39-48, 1980; Woltring & Huiskes (1990), section
    "Simultaneous Multiframe Analytical Calibration (SMAC)"; Z. Zhang, IEEE TPAMI
    22(11), 2000.
    """
    model = check_grid(grid_points)
    uv = view_points(image_points, model.shape[0])
    if uv.ndim != 4:
        raise CalibrationError(f"image_points must have shape (C, V, P, 2), got {uv.shape}")
    n_cam, n_view = uv.shape[:2]
    if n_cam < 2:
        raise CalibrationError(f"SMAC needs at least 2 cameras, got {n_cam}")
    cam_names = [f"cam{c + 1}" for c in range(n_cam)] if names is None else list(names)
    if len(cam_names) != n_cam:
        raise CalibrationError(f"names has {len(cam_names)} entries for {n_cam} cameras")
    if not 0 <= reference_view < n_view:
        raise CalibrationError(f"reference_view {reference_view} is not one of the {n_view} views")
    sizes = _sizes(image_size, n_cam)
    usable = np.array([usable_views(model, uv[c]) for c in range(n_cam)])
    own: list[PlanarCalibration] = []
    per_camera: list[dict[int, tuple[FloatArray, FloatArray]]] = []
    for c in range(n_cam):
        views = np.flatnonzero(usable[c])
        if views.size < MIN_VIEWS:
            raise CalibrationError(
                f"camera {cam_names[c]} sees the grid in {views.size} usable views (>= 4 "
                f"non-collinear points); SMAC needs at least {MIN_VIEWS} per camera"
            )
        try:
            cal = calibrate_intrinsics(
                model, uv[c, views], sizes[c], distortion=distortion, skew=skew, max_iter=max_iter
            )
        except CalibrationError as exc:
            raise CalibrationError(f"camera {cam_names[c]}: {exc}") from None
        own.append(cal)
        per_camera.append(
            {int(v): (cal.rotations[i], cal.translations[i]) for i, v in enumerate(views)}
        )
    if not usable[:, reference_view].any():
        raise CalibrationError(
            f"no camera sees the reference view {reference_view} with >= 4 non-collinear "
            "points: it cannot define the world frame"
        )
    cam_poses, view_poses = _chain_poses(per_camera, reference_view, cam_names)
    used = np.array(sorted(view_poses))
    state = BundleState(
        intrinsics=np.array(
            [[*cal.camera.K[[0, 1, 0, 1, 0], [0, 1, 2, 2, 1]], *cal.camera.dist] for cal in own]
        ),
        cam_R=np.array([R for R, _ in cam_poses]),
        cam_t=np.array([t for _, t in cam_poses]),
        pose_R=np.array([view_poses[v][0] for v in used]),
        pose_t=np.array([view_poses[v][1] for v in used]),
    )
    free = camera_mask(distortion, skew=skew, extrinsics=True)
    result = adjust(
        state,
        model,
        uv[:, used],
        camera_free=free,
        pose_free=used != reference_view,
        max_iter=max_iter,
    )
    st = result.state
    for c, cal in enumerate(own):
        check_determined(result.camera_std[c], cal.camera.K, f"camera {cam_names[c]}: ")
    cameras = [
        Camera(
            [[p[0], p[4], p[2]], [0.0, p[1], p[3]], [0.0, 0.0, 1.0]],
            p[5:],
            st.cam_R[c],
            st.cam_t[c],
            sizes[c],
            cam_names[c],
        )
        for c, p in enumerate(st.intrinsics)
    ]
    poses = np.full((n_view, 4, 4), np.nan)
    poses[used, :3, :3] = st.pose_R
    poses[used, :3, 3] = st.pose_t
    poses[used, 3] = [0.0, 0.0, 0.0, 1.0]
    residuals = np.full(uv.shape, np.nan)
    residuals[:, used] = result.residuals
    d2 = np.sum(residuals**2, axis=-1).reshape(n_cam, -1)
    rms = np.sqrt(np.nanmean(d2, axis=1))
    report: dict[str, Any] = {
        "method": "SMAC (Woltring 1980): planar grid, joint bundle adjustment",
        "reference_view": reference_view,
        "unused_views": sorted(set(range(n_view)) - set(used.tolist())),
        "views_per_camera": dict(
            zip(cam_names, np.count_nonzero(usable, axis=1).tolist(), strict=True)
        ),
        "observations_per_camera": dict(
            zip(cam_names, np.count_nonzero(np.isfinite(d2), axis=1).tolist(), strict=True)
        ),
        "rms_px": dict(zip(cam_names, rms.tolist(), strict=True)),
        "initial_rms_px": {n: cal.rms_px for n, cal in zip(cam_names, own, strict=True)},
        "std": {
            n: {CAMERA_PARAMS[i]: float(result.camera_std[c, i]) for i in np.flatnonzero(free)}
            for c, n in enumerate(cam_names)
        },
        "iterations": result.iterations,
    }
    return SmacCalibration(Rig(cameras), poses, rms, residuals, report)
