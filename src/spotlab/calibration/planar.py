"""Intrinsic calibration of one camera from a planar grid seen in several views (Zhang 2000).

Per view a normalised DLT homography between the grid plane and the image; the closed
form for the image of the absolute conic ``B = K^-T K^-1`` from the two constraints each
homography gives; ``K`` from ``B``; each view's pose from its homography; then all of
them (intrinsics, distortion, every pose) adjusted together on the image residuals.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from spotlab.calibration._bundle import BundleState, adjust
from spotlab.calibration.dlt import DISTORTION_TERMS, _normalisation
from spotlab.core.errors import CalibrationError
from spotlab.geometry import Camera

__all__ = ["PlanarCalibration", "calibrate_intrinsics", "fit_homography"]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

#: Fewest grid points per view: a homography has 8 degrees of freedom.
MIN_POINTS = 4
#: Largest standard error of fx, fy, cx or cy accepted, as a fraction of the focal length.
MAX_RELATIVE_STD = 0.05


@dataclass(frozen=True)
class PlanarCalibration:
    """Outcome of :func:`calibrate_intrinsics`.

    Attributes
    ----------
    camera : Camera
        The calibrated camera, posed at the first view (world = grid frame of view 0).
    rotations : ndarray, shape (V, 3, 3)
        Grid-to-camera rotation of each view (``x_cam = R_v P + t_v``).
    translations : ndarray, shape (V, 3)
        Grid-to-camera translation of each view (grid units).
    rms_px : float
        Root mean square of the residual distances over all points (px).
    view_rms_px : ndarray, shape (V,)
        The same per view (px).
    residuals : ndarray, shape (V, P, 2)
        Observed minus modelled image coordinates (px), NaN where not observed.
    std : dict of str to float
        Standard errors of the estimated intrinsics and distortion terms (px or
        dimensionless), from the normal matrix scaled by the residual variance.
    linear_K : ndarray, shape (3, 3)
        The closed-form intrinsics before adjustment.
    iterations : int
        Levenberg-Marquardt steps of the adjustment.
    """

    camera: Camera
    rotations: FloatArray
    translations: FloatArray
    rms_px: float
    view_rms_px: FloatArray
    residuals: FloatArray
    std: dict[str, float]
    linear_K: FloatArray
    iterations: int


def check_grid(object_points: Any) -> FloatArray:
    """Grid points (P, 3) with Z = 0, validated."""
    model = np.asarray(object_points, dtype=np.float64)
    if model.ndim != 2 or model.shape[1] not in (2, 3):
        raise CalibrationError(f"object_points must have shape (P, 2) or (P, 3), got {model.shape}")
    if not np.all(np.isfinite(model)):
        raise CalibrationError("object_points hold NaN or infinite values")
    if model.shape[1] == 2:
        model = np.column_stack([model, np.zeros(model.shape[0])])
    extent = float(np.ptp(model[:, :2], axis=0).max()) if model.shape[0] else 0.0
    if np.any(np.abs(model[:, 2]) > 1e-9 * max(extent, 1e-300)):
        raise CalibrationError("object_points must lie in the grid plane Z = 0")
    if model.shape[0] < MIN_POINTS:
        raise CalibrationError(f"the grid needs at least {MIN_POINTS} points, got {model.shape[0]}")
    if _collinear(model[:, :2]):
        raise CalibrationError("the grid points are collinear (or coincide)")
    return model


def _collinear(points: FloatArray) -> bool:
    s = np.linalg.svd(points - points.mean(axis=0), compute_uv=False)
    return not (s[0] > 0.0 and s[1] > 1e-6 * s[0])


def usable_views(model: FloatArray, image_points: FloatArray) -> BoolArray:
    """Views (V,) with at least 4 observed, non-collinear grid points."""
    seen = np.all(np.isfinite(image_points), axis=-1)
    ok = np.zeros(image_points.shape[0], dtype=bool)
    for v in range(image_points.shape[0]):
        idx = seen[v]
        if np.count_nonzero(idx) >= MIN_POINTS:
            ok[v] = not (_collinear(model[idx, :2]) or _collinear(image_points[v, idx]))
    return ok


def fit_homography(plane_points: Any, image_points: Any) -> FloatArray:
    """Homography from plane to image by the normalised DLT (Hartley 1997).

    Parameters
    ----------
    plane_points : array_like, shape (N, 2)
        Points of the plane (any length unit), N >= 4, not collinear.
    image_points : array_like, shape (N, 2)
        Their image coordinates (px).

    Returns
    -------
    ndarray, shape (3, 3)
        ``H`` with ``(u, v, 1) ~ H (X, Y, 1)``, scaled so that ``H[2, 2] = 1`` when
        possible (else to unit Frobenius norm).

    Raises
    ------
    CalibrationError
        Fewer than 4 points, NaN, collinear points on either side.
    """
    X = np.asarray(plane_points, dtype=np.float64)
    uv = np.asarray(image_points, dtype=np.float64)
    if X.ndim != 2 or X.shape[1] != 2 or uv.shape != X.shape:
        raise CalibrationError(
            f"plane_points and image_points must both have shape (N, 2), got {X.shape}, {uv.shape}"
        )
    if not (np.all(np.isfinite(X)) and np.all(np.isfinite(uv))):
        raise CalibrationError("homography: NaN or infinite coordinates")
    if X.shape[0] < MIN_POINTS:
        raise CalibrationError(f"a homography needs at least 4 points, got {X.shape[0]}")
    if _collinear(X) or _collinear(uv):
        raise CalibrationError("homography: the points are collinear")
    T_x, T_u = _normalisation(X), _normalisation(uv)
    xn = X @ T_x[:2, :2].T + T_x[:2, 2]
    un = uv @ T_u[:2, :2].T + T_u[:2, 2]
    n = X.shape[0]
    xh = np.column_stack([xn, np.ones(n)])
    A = np.zeros((2 * n, 9))
    A[0::2, 0:3] = xh
    A[0::2, 6:9] = -un[:, :1] * xh
    A[1::2, 3:6] = xh
    A[1::2, 6:9] = -un[:, 1:] * xh
    _, s, vt = np.linalg.svd(A)
    if s[-2] <= 1e-9 * s[0]:
        raise CalibrationError("homography: the points do not determine a unique homography")
    H = np.linalg.solve(T_u, vt[-1].reshape(3, 3)) @ T_x
    return H / H[2, 2] if abs(H[2, 2]) > 1e-12 * np.abs(H).max() else H / np.linalg.norm(H)


def _v(H: FloatArray, i: int, j: int) -> FloatArray:
    """Zhang's v_ij: ``h_i' B h_j = v_ij' b`` with ``b = (B11, B12, B22, B13, B23, B33)``."""
    a, c = H[:, i], H[:, j]
    return np.array(
        [a[0] * c[0], a[0] * c[1] + a[1] * c[0], a[1] * c[1],
         a[2] * c[0] + a[0] * c[2], a[2] * c[1] + a[1] * c[2], a[2] * c[2]]
    )  # fmt: skip


def closed_form_intrinsics(homographies: Sequence[FloatArray], *, skew: bool) -> FloatArray:
    """``K`` from the homographies of >= 3 views (2 with zero skew); Zhang 2000, Appendix B.

    The homographies should be expressed in well-scaled image coordinates (about unit
    size): the caller normalises them.
    """
    rows = []
    for H in homographies:
        H = H / np.linalg.norm(H)
        rows += [_v(H, 0, 1), _v(H, 0, 0) - _v(H, 1, 1)]
    if not skew:
        rows.append(np.array([0.0, 1.0, 0.0, 0.0, 0.0, 0.0]) * np.abs(np.array(rows)).max())
    Vm = np.array(rows)
    _, s, vt = np.linalg.svd(Vm)
    if Vm.shape[0] < 5 or s[4] < 1e-8 * s[0]:
        raise CalibrationError(
            "the views do not determine the intrinsics: the grid planes are all parallel "
            "to each other (or too few distinct orientations); tilt the grid between views"
        )
    b = vt[-1]
    B11, B12, B22, B13, B23, B33 = b if b[0] > 0 else -b
    det = B11 * B22 - B12 * B12
    if not det > 0.0:
        raise CalibrationError(
            "the closed-form image of the absolute conic is not positive definite: the "
            "views are too similar (nearly parallel grid planes) or the data too noisy"
        )
    v0 = (B12 * B13 - B11 * B23) / det
    lam = B33 - (B13 * B13 + v0 * (B12 * B13 - B11 * B23)) / B11
    if not lam / B11 > 0.0:
        raise CalibrationError(
            "the closed-form intrinsics are imaginary (lambda/B11 <= 0): the views are too "
            "similar (nearly parallel grid planes) or the data too noisy"
        )
    alpha = np.sqrt(lam / B11)
    beta = np.sqrt(lam * B11 / det)
    gamma = -B12 * alpha * alpha * beta / lam if skew else 0.0
    u0 = gamma * v0 / beta - B13 * alpha * alpha / lam
    return np.array([[alpha, gamma, u0], [0.0, beta, v0], [0.0, 0.0, 1.0]])


def pose_from_homography(K: FloatArray, H: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Grid-to-camera ``R`` (3, 3), ``t`` (3,) of a view: ``H ~ K [r1 r2 t]``, orthonormalised."""
    M = np.linalg.solve(K, H)
    lam = 2.0 / (np.linalg.norm(M[:, 0]) + np.linalg.norm(M[:, 1]))
    if M[2, 2] < 0.0:  # the grid lies in front of the camera
        lam = -lam
    r1, r2, t = lam * M[:, 0], lam * M[:, 1], lam * M[:, 2]
    u, _, vt = np.linalg.svd(np.column_stack([r1, r2, np.cross(r1, r2)]))
    R = u @ np.diag([1.0, 1.0, np.linalg.det(u @ vt)]) @ vt
    return R, t


def _scaling(image_size: tuple[int, int]) -> FloatArray:
    """Image coordinates to about [-1, 1]: conditions Zhang's linear system."""
    w, h = image_size
    s = 2.0 / (w + h)
    return np.array([[s, 0.0, -s * w / 2], [0.0, s, -s * h / 2], [0.0, 0.0, 1.0]])


def initial_views(
    model: FloatArray, image_points: FloatArray, image_size: tuple[int, int], *, skew: bool
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Closed-form ``K`` (3, 3) and per-view grid-to-camera ``R`` (V, 3, 3), ``t`` (V, 3).

    Every view must be usable (:func:`usable_views`).
    """
    N = _scaling(image_size)
    homographies = []
    for uv in image_points:
        idx = np.all(np.isfinite(uv), axis=1)
        homographies.append(fit_homography(model[idx, :2], uv[idx]))
    K_n = closed_form_intrinsics([N @ H for H in homographies], skew=skew)
    K = np.asarray(np.linalg.solve(N, K_n), dtype=np.float64)
    K /= K[2, 2]
    poses = [pose_from_homography(K, H) for H in homographies]
    normals = np.array([R[:, 2] for R, _ in poses])
    spread = np.linalg.svd(normals - normals.mean(axis=0), compute_uv=False)[0]
    if spread < np.sin(np.radians(1.0)):
        raise CalibrationError(
            "the grid planes of all views are parallel to each other (within 1 degree): "
            "the intrinsics are not determined; tilt the grid between views"
        )
    return K, np.array([R for R, _ in poses]), np.array([t for _, t in poses])


def distortion_mask(distortion: bool | Sequence[str]) -> BoolArray:
    """Which of ``k1, k2, p1, p2, k3`` are estimated, shape (5,)."""
    if distortion is True:
        return np.ones(5, dtype=bool)
    if distortion is False:
        return np.zeros(5, dtype=bool)
    names = [distortion] if isinstance(distortion, str) else list(distortion)
    unknown = sorted(set(names) - set(DISTORTION_TERMS))
    if unknown:
        raise CalibrationError(
            f"unknown distortion terms {unknown}: choose from {DISTORTION_TERMS}"
        )
    return np.array([term in names for term in DISTORTION_TERMS])


def camera_mask(distortion: bool | Sequence[str], *, skew: bool, extrinsics: bool) -> BoolArray:
    """Free entries of a bundle camera block, shape (16,)."""
    return np.concatenate(
        [[True] * 4, [skew], distortion_mask(distortion), [extrinsics] * 6]
    ).astype(bool)


def view_points(image_points: Any, n_points: int, what: str = "image_points") -> FloatArray:
    """Image points as float (..., P, 2), NaN allowed, infinities refused."""
    uv = np.asarray(image_points, dtype=np.float64)
    if uv.ndim < 3 or uv.shape[-2:] != (n_points, 2):
        raise CalibrationError(
            f"{what} must have shape (..., {n_points}, 2) for a grid of {n_points} points, "
            f"got {uv.shape}"
        )
    if np.any(np.isinf(uv)):
        raise CalibrationError(f"{what} hold infinite values")
    return uv


def image_size_checked(image_size: Any) -> tuple[int, int]:
    """``(width, height)`` as positive whole pixels, else :class:`CalibrationError`."""
    try:
        w, h = (float(v) for v in image_size)
    except (TypeError, ValueError):
        raise CalibrationError(
            f"image_size must be (width, height) in px, got {image_size!r}"
        ) from None
    if not (w > 0 and h > 0 and w.is_integer() and h.is_integer()):
        raise CalibrationError(f"image_size must be positive whole pixels, got {image_size!r}")
    return int(w), int(h)


def check_determined(std: FloatArray, K: FloatArray, what: str = "") -> None:
    """Refuse intrinsics the data leave undetermined.

    Parameters
    ----------
    std : ndarray, shape (16,)
        Standard errors of a bundle camera block (``fx, fy, cx, cy`` first; px).
    K : ndarray, shape (3, 3)
        The estimated intrinsics.
    what : str
        Prefix of the message (which camera).

    Raises
    ------
    CalibrationError
        When a standard error of ``fx, fy, cx, cy`` exceeds :data:`MAX_RELATIVE_STD` of
        the focal length: noisy views of (nearly) parallel grid planes, or planes that
        all turn about one axis, give a minimum but no answer.
    """
    focal = 0.5 * (K[0, 0] + K[1, 1])
    rel = std[:4] / focal
    worst = int(np.argmax(np.where(np.isnan(rel), -np.inf, rel)))
    if rel[worst] > MAX_RELATIVE_STD:
        name = ("fx", "fy", "cx", "cy")[worst]
        raise CalibrationError(
            f"{what}the views do not determine the intrinsics: the standard error of {name} "
            f"is {std[worst]:.3g} px ({100 * rel[worst]:.0f} % of the focal length); the "
            "grid planes are (nearly) parallel or all turn about one axis: tilt the grid "
            "about different axes between views"
        )


def calibrate_intrinsics(
    object_points: Any,
    image_points: Any,
    image_size: tuple[int, int],
    *,
    distortion: bool | Sequence[str] = ("k1", "k2"),
    skew: bool = False,
    name: str = "",
    max_iter: int = 100,
) -> PlanarCalibration:
    """Calibrate one camera from a planar grid seen at several orientations (Zhang 2000).

    Parameters
    ----------
    object_points : array_like, shape (P, 2) or (P, 3)
        The grid points in the grid's own frame (any length unit, Z = 0).
    image_points : array_like, shape (V, P, 2)
        Their image coordinates in each of V views (px); NaN marks a point not seen.
        Every view needs at least 4 points, not collinear.
    image_size : (int, int)
        ``(width, height)`` (px).
    distortion : bool or sequence of str
        Distortion terms to estimate, of ``k1, k2, p1, p2, k3`` (OpenCV's order);
        ``True`` for all five, ``False`` for none. Default: Zhang's ``k1, k2``.
    skew : bool
        Estimate the shear ``s = K[0, 1]`` too (Zhang's gamma); zero otherwise.
    name : str
        Label of the returned camera.
    max_iter : int
        Levenberg-Marquardt steps allowed.

    Returns
    -------
    PlanarCalibration
        ``camera`` (posed at view 0), per-view ``rotations`` and ``translations``,
        ``rms_px``, ``view_rms_px``, ``residuals`` (V, P, 2), standard errors.

    Raises
    ------
    CalibrationError
        Too few views (3, or 2 without skew), a view with fewer than 4 points or
        collinear points, a grid that is not planar or is collinear, NaN in the grid,
        grid planes all parallel to each other, or intrinsics the views leave
        undetermined (a standard error of ``fx, fy, cx, cy`` above 5 % of the focal
        length).

    Notes
    -----
    For view ``i`` the homography ``H = [h1 h2 h3] ~ K [r1 r2 t]`` (normalised DLT)
    gives two linear constraints on ``B = K^-T K^-1``: ``h1' B h2 = 0`` and
    ``h1' B h1 = h2' B h2``, written ``v12' b = 0`` and ``(v11 - v22)' b = 0`` with
    ``b = (B11, B12, B22, B13, B23, B33)`` (Zhang 2000, Eq. 8-9); with zero skew the row
    ``B12 = 0`` is added. ``b`` is the right singular vector of the smallest singular
    value and ``K`` follows in closed form (Appendix B). The pose: ``r1 = l K^-1 h1``,
    ``r2 = l K^-1 h2``, ``r3 = r1 x r2``, ``t = l K^-1 h3``, orthonormalised by SVD.
    Finally ``fx, fy, cx, cy`` (and ``s``), the chosen distortion terms and all poses
    minimise the image residuals (Levenberg-Marquardt, the pose blocks eliminated by
    Schur complement, analytic derivatives). Distortion is Brown's model on ideal
    normalised coordinates, OpenCV's convention; Zhang's radial ``k1, k2`` are OpenCV's.
    Reference: Z. Zhang, "A flexible new technique for camera calibration", IEEE TPAMI
    22(11):1330-1334, 2000 (MSR-TR-98-71).
    """
    model = check_grid(object_points)
    uv = view_points(image_points, model.shape[0])
    if uv.ndim != 3:
        raise CalibrationError(f"image_points must have shape (V, P, 2), got {uv.shape}")
    size = image_size_checked(image_size)
    need = 3 if skew else 2
    if uv.shape[0] < need:
        raise CalibrationError(
            f"Zhang's method needs at least {need} views ({'with' if skew else 'without'} "
            f"skew), got {uv.shape[0]}"
        )
    seen = np.all(np.isfinite(uv), axis=-1)
    for v in range(uv.shape[0]):
        count = int(np.count_nonzero(seen[v]))
        if count < MIN_POINTS:
            raise CalibrationError(f"view {v} has {count} observed points; at least 4 needed")
        if _collinear(uv[v, seen[v]]) or _collinear(model[seen[v], :2]):
            raise CalibrationError(f"view {v}: the observed points are collinear")
    free = camera_mask(distortion, skew=skew, extrinsics=False)
    K0, Rs, ts = initial_views(model, uv, size, skew=skew)
    state = BundleState(
        intrinsics=np.array([[K0[0, 0], K0[1, 1], K0[0, 2], K0[1, 2], K0[0, 1], 0, 0, 0, 0, 0]]),
        cam_R=np.eye(3)[None],
        cam_t=np.zeros((1, 3)),
        pose_R=Rs,
        pose_t=ts,
    )
    result = adjust(
        state,
        model,
        uv[None],
        camera_free=free,
        pose_free=np.ones(uv.shape[0], dtype=bool),
        max_iter=max_iter,
    )
    p = result.state.intrinsics[0]
    K = np.array([[p[0], p[4], p[2]], [0.0, p[1], p[3]], [0.0, 0.0, 1.0]])
    check_determined(result.camera_std[0], K)
    Rs, ts = result.state.pose_R, result.state.pose_t
    camera = Camera(K, p[5:], Rs[0], ts[0], size, name)
    residuals = result.residuals[0]
    d2 = np.sum(residuals**2, axis=-1)
    view_rms = np.sqrt(np.nanmean(d2, axis=1))
    names = ("fx", "fy", "cx", "cy", "skew", *DISTORTION_TERMS)
    std = {n: float(result.camera_std[0, i]) for i, n in enumerate(names) if free[i]}
    return PlanarCalibration(
        camera=camera,
        rotations=Rs,
        translations=ts,
        rms_px=float(np.sqrt(np.nanmean(d2))),
        view_rms_px=view_rms,
        residuals=residuals,
        std=std,
        linear_K=K0,
        iterations=result.iterations,
    )
