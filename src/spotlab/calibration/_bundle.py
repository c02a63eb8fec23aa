"""Bundle adjustment of cameras that observe one rigid point set at several unknown poses.

The engine behind Zhang's intrinsic calibration (one camera, the grid poses are the view
poses) and SMAC (several cameras, one grid pose fixed as the world frame). Unknowns:

* per camera a block of 16 numbers ``(fx, fy, cx, cy, s, k1, k2, p1, p2, k3, w, t)``: the
  intrinsics (px), the Brown distortion in OpenCV's order, a rotation increment ``w``
  (rad, ``R = exp([w]x) R0``) and the translation;
* per pose 6 numbers ``(w, t)``: the rigid motion taking the model into the world,
  ``X = R_v P + t_v``.

Any subset can be held fixed. The normal equations have the arrow structure of bundle
adjustment: the pose blocks (6 x 6 each) are eliminated first (Schur complement), so one
Levenberg-Marquardt step costs a dense solve of the camera parameters only (at most
16 per camera) whatever the number of poses and points. Derivatives are analytic.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from spotlab.core.errors import CalibrationError
from spotlab.geometry.distortion import _jacobian as distortion_jacobian
from spotlab.geometry.distortion import distort_normalized

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

#: Names of the 16 entries of a camera block.
CAMERA_PARAMS = (
    "fx", "fy", "cx", "cy", "skew", "k1", "k2", "p1", "p2", "k3",
    "w1", "w2", "w3", "t1", "t2", "t3",
)  # fmt: skip


@dataclass
class BundleState:
    """Cameras and poses of a bundle adjustment.

    Attributes
    ----------
    intrinsics : ndarray, shape (C, 10)
        ``fx, fy, cx, cy, s`` (px) and ``k1, k2, p1, p2, k3`` per camera.
    cam_R : ndarray, shape (C, 3, 3)
        World-to-camera rotations.
    cam_t : ndarray, shape (C, 3)
        Camera translations (``x_cam = R X + t``).
    pose_R : ndarray, shape (V, 3, 3)
        Model-to-world rotations of the poses.
    pose_t : ndarray, shape (V, 3)
        Model-to-world translations.
    """

    intrinsics: FloatArray
    cam_R: FloatArray
    cam_t: FloatArray
    pose_R: FloatArray
    pose_t: FloatArray

    def copy(self) -> BundleState:
        return BundleState(
            self.intrinsics.copy(),
            self.cam_R.copy(),
            self.cam_t.copy(),
            self.pose_R.copy(),
            self.pose_t.copy(),
        )


@dataclass(frozen=True)
class BundleResult:
    """Outcome of :func:`adjust`.

    Attributes
    ----------
    state : BundleState
        The adjusted cameras and poses.
    residuals : ndarray, shape (C, V, P, 2)
        Observed minus modelled image coordinates (px), NaN where not observed.
    camera_std : ndarray, shape (C, 16)
        Standard errors of the camera parameters from the inverse of the reduced
        normal matrix scaled by the residual variance; NaN for fixed ones.
    iterations : int
        Levenberg-Marquardt steps taken (accepted or not).
    """

    state: BundleState
    residuals: FloatArray
    camera_std: FloatArray
    iterations: int


def _cross_rows(y: FloatArray, M: FloatArray) -> FloatArray:
    """``M @ (-[y]x)`` for row-stacked ``M`` (..., 2, 3) and vectors ``y`` (..., 3)."""
    # Row r of M times -[y]x is (y x r): the derivative of r . (exp([w]x) y) at w = 0.
    return np.cross(y[..., None, :], M)


def _project(
    state: BundleState, model: FloatArray, with_jacobian: bool
) -> tuple[FloatArray, FloatArray, FloatArray | None, FloatArray | None]:
    """Pixels (C, V, P, 2), depths (C, V, P) and Jacobians w.r.t. camera and pose blocks."""
    RP = np.einsum("vij,pj->vpi", state.pose_R, model)
    X = RP + state.pose_t[:, None, :]
    RX = np.einsum("cij,vpj->cvpi", state.cam_R, X)
    xc = RX + state.cam_t[:, None, None, :]
    z = xc[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        xy = xc[..., :2] / z[..., None]
    n_cam = state.intrinsics.shape[0]
    uv = np.empty_like(xy)
    xyd = np.empty_like(xy)
    for c in range(n_cam):
        fx, fy, cx, cy, s = state.intrinsics[c, :5]
        xyd[c] = distort_normalized(xy[c], state.intrinsics[c, 5:])
        uv[c, ..., 0] = fx * xyd[c, ..., 0] + s * xyd[c, ..., 1] + cx
        uv[c, ..., 1] = fy * xyd[c, ..., 1] + cy
    if not with_jacobian:
        return uv, z, None, None

    shape = xy.shape[:-1]
    x, y = xy[..., 0], xy[..., 1]
    J_cam = np.zeros((*shape, 2, 16))
    J_cam[..., 0, 0] = xyd[..., 0]
    J_cam[..., 1, 1] = xyd[..., 1]
    J_cam[..., 0, 2] = 1.0
    J_cam[..., 1, 3] = 1.0
    J_cam[..., 0, 4] = xyd[..., 1]
    # d(x_d, y_d) / d(k1, k2, p1, p2, k3), then through the linear intrinsics.
    r2 = x * x + y * y
    d_dist = np.zeros((*shape, 2, 5))
    d_dist[..., 0, 0], d_dist[..., 1, 0] = x * r2, y * r2
    d_dist[..., 0, 1], d_dist[..., 1, 1] = x * r2 * r2, y * r2 * r2
    d_dist[..., 0, 2], d_dist[..., 1, 2] = 2.0 * x * y, r2 + 2.0 * y * y
    d_dist[..., 0, 3], d_dist[..., 1, 3] = r2 + 2.0 * x * x, 2.0 * x * y
    d_dist[..., 0, 4], d_dist[..., 1, 4] = x * r2**3, y * r2**3
    A = np.zeros((n_cam, 2, 2))
    A[:, 0, 0] = state.intrinsics[:, 0]
    A[:, 0, 1] = state.intrinsics[:, 4]
    A[:, 1, 1] = state.intrinsics[:, 1]
    J_cam[..., 5:10] = np.einsum("cij,cvpjk->cvpik", A, d_dist)
    # d(u, v) / d(x_cam): linear intrinsics, distortion, perspective division.
    D = np.empty((*shape, 2, 2))
    for c in range(n_cam):
        D[c] = distortion_jacobian(xy[c], state.intrinsics[c, 5:])
    persp = np.zeros((*shape, 2, 3))
    iz = 1.0 / z
    persp[..., 0, 0] = iz
    persp[..., 1, 1] = iz
    persp[..., 0, 2] = -x * iz
    persp[..., 1, 2] = -y * iz
    M = np.einsum("cij,cvpjk,cvpkl->cvpil", A, D, persp)
    J_cam[..., 10:13] = _cross_rows(RX, M)
    J_cam[..., 13:16] = M
    MR = np.einsum("cvpij,cjk->cvpik", M, state.cam_R)
    J_pose = np.concatenate([_cross_rows(RP, MR), MR], axis=-1)
    return uv, z, J_cam, J_pose


def _rotate(R: FloatArray, w: FloatArray) -> FloatArray:
    out = Rotation.from_rotvec(w).as_matrix() @ R
    u, _, vt = np.linalg.svd(out)  # keep them orthonormal over many steps
    return np.asarray(u @ vt)


def _apply(state: BundleState, d_cam: FloatArray, d_pose: FloatArray) -> BundleState:
    new = state.copy()
    new.intrinsics += d_cam[:, :10]
    new.cam_R = _rotate(state.cam_R, d_cam[:, 10:13])
    new.cam_t += d_cam[:, 13:16]
    new.pose_R = _rotate(state.pose_R, d_pose[:, :3])
    new.pose_t += d_pose[:, 3:]
    return new


def _residuals(
    state: BundleState, model: FloatArray, obs: FloatArray, seen: BoolArray
) -> FloatArray:
    uv, z, _, _ = _project(state, model, with_jacobian=False)
    res = np.where(seen[..., None], obs - uv, 0.0)
    if np.any(seen & ~(z > 0.0)):
        res[...] = np.inf  # a trial step that puts observed points behind a camera
    return res


def _normal_equations(
    state: BundleState,
    model: FloatArray,
    res: FloatArray,
    seen: BoolArray,
    free: NDArray[np.intp],
    pose_free: BoolArray,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """Blocks of J'J and J'r: cameras U (C, n, n), poses V (V, 6, 6), W (C, V, n, 6)."""
    _, _, J_cam_full, J_pose_full = _project(state, model, with_jacobian=True)
    assert J_cam_full is not None and J_pose_full is not None
    J_cam = J_cam_full[..., free] * seen[..., None, None]
    J_pose = J_pose_full * (seen & pose_free[None, :, None])[..., None, None]
    U = np.einsum("cvpia,cvpib->cab", J_cam, J_cam)
    V = np.einsum("cvpia,cvpib->vab", J_pose, J_pose)
    V[~pose_free] = np.eye(6)
    W = np.einsum("cvpia,cvpib->cvab", J_cam, J_pose)
    g_cam = np.einsum("cvpia,cvpi->ca", J_cam, res)
    g_pose = np.einsum("cvpia,cvpi->va", J_pose, res)
    return U, V, W, g_cam, g_pose


def _reduced(
    U: FloatArray, V: FloatArray, W: FloatArray, lam: float
) -> tuple[FloatArray, FloatArray]:
    """Damped Schur complement ``U - W V^-1 W'`` (C n, C n) and the damped ``V^-1``."""
    n_cam, n_free = U.shape[:2]
    Ud = U + lam * np.einsum("cii->ci", U)[..., None] * np.eye(n_free)
    Vd = V + lam * np.einsum("vii->vi", V)[..., None] * np.eye(6)
    Vinv = np.linalg.inv(Vd)
    S = -np.einsum("cvab,vbd,evfd->caef", W, Vinv, W)
    S[np.arange(n_cam), :, np.arange(n_cam), :] += Ud
    return S.reshape(n_cam * n_free, n_cam * n_free), Vinv


def _inverse_diagonal(S: FloatArray) -> FloatArray:
    """Diagonal of ``S^-1`` for a symmetric positive semi-definite ``S``.

    Directions the data do not determine (eigenvalues below 1e-15 of the largest after
    Jacobi scaling) count with that floor: their variances come out huge, not zero as a
    pseudo-inverse would make them.
    """
    d = np.sqrt(np.maximum(np.diag(S), 1e-300))
    evals, evecs = np.linalg.eigh(S / np.outer(d, d))
    evals = np.maximum(evals, 1e-15 * max(float(evals[-1]), 1e-300))
    return np.asarray(np.einsum("ij,j,ij->i", evecs, 1.0 / evals, evecs) / d**2)


def adjust(
    state: BundleState,
    model: FloatArray,
    observations: FloatArray,
    *,
    camera_free: BoolArray,
    pose_free: BoolArray,
    max_iter: int = 100,
    tol: float = 1e-12,
) -> BundleResult:
    """Levenberg-Marquardt on the image residuals, poses eliminated by Schur complement.

    Parameters
    ----------
    state : BundleState
        Starting values (not modified).
    model : ndarray, shape (P, 3)
        The rigid point set in its own frame.
    observations : ndarray, shape (C, V, P, 2)
        Observed pixels, NaN where a camera does not see a point.
    camera_free : ndarray of bool, shape (16,)
        Which camera block entries (:data:`CAMERA_PARAMS` order) are estimated; the
        same for every camera.
    pose_free : ndarray of bool, shape (V,)
        Which poses are estimated (a fixed pose defines the world frame).
    max_iter : int
        Levenberg-Marquardt steps allowed.
    tol : float
        Stop when a step lowers the cost by less than this fraction.

    Returns
    -------
    BundleResult

    Raises
    ------
    CalibrationError
        When the start puts observed points behind a camera. (A trial step that does
        so is refused; the adjustment stops when no step lowers the cost.)
    """
    seen = np.all(np.isfinite(observations), axis=-1)
    obs = np.where(seen[..., None], observations, 0.0)
    free = np.flatnonzero(camera_free)
    n_cam, n_free = state.intrinsics.shape[0], free.size
    res = _residuals(state, model, obs, seen)
    cost = float(np.sum(res**2))
    if not np.isfinite(cost):
        raise CalibrationError(
            "bundle adjustment: observed points lie behind a camera at the start"
        )
    lam, iterations = 1e-3, 0
    for iterations in range(1, max_iter + 1):  # noqa: B007
        U, V, W, g_cam, g_pose = _normal_equations(state, model, res, seen, free, pose_free)
        while True:
            S, Vinv = _reduced(U, V, W, lam)
            rhs = (g_cam - np.einsum("cvab,vbd,vd->ca", W, Vinv, g_pose)).ravel()
            scale = 1.0 / np.sqrt(np.maximum(np.diag(S), 1e-300))
            try:
                dc = scale * np.linalg.solve(S * np.outer(scale, scale), rhs * scale)
            except np.linalg.LinAlgError:
                dc = np.full_like(rhs, np.nan)
            dc = dc.reshape(n_cam, n_free)
            dp = np.einsum("vab,vb->va", Vinv, g_pose - np.einsum("cvab,ca->vb", W, dc))
            d_cam = np.zeros((n_cam, 16))
            d_cam[:, free] = dc
            dp[~pose_free] = 0.0
            trial = _apply(state, d_cam, dp) if np.all(np.isfinite(dc)) else state
            new_res = _residuals(trial, model, obs, seen)
            new_cost = float(np.sum(new_res**2))
            if np.isfinite(new_cost) and new_cost < cost:
                break
            lam *= 10.0
            if lam > 1e12:
                break
        if not (np.isfinite(new_cost) and new_cost < cost):
            break  # no step lowers the cost: at the minimum to working precision
        improvement = (cost - new_cost) / max(cost, 1e-300)
        state, res, cost = trial, new_res, new_cost
        lam = max(lam / 10.0, 1e-12)
        if improvement < tol:
            break
    n_obs = 2 * int(np.count_nonzero(seen))
    n_par = n_cam * n_free + 6 * int(np.count_nonzero(pose_free))
    sigma2 = cost / max(n_obs - n_par, 1)
    U, V, W, _, _ = _normal_equations(state, model, res, seen, free, pose_free)
    S, _ = _reduced(U, V, W, 0.0)
    std = np.full((n_cam, 16), np.nan)
    std[:, free] = np.sqrt(sigma2 * _inverse_diagonal(S)).reshape(n_cam, n_free)
    uv, _, _, _ = _project(state, model, with_jacobian=False)
    residuals = np.where(seen[..., None], observations - uv, np.nan)
    return BundleResult(state, residuals, std, iterations)
