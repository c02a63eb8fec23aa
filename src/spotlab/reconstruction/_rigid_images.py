"""Rigid-body pose straight from image points, even when no marker is seen twice.

Woltring & Huiskes (1990), after Woltring (1982): with partial observations (marker 1
seen by camera 1 only, marker 2 by camera 2 only, ...) the markers cannot be
reconstructed one by one, but the six pose parameters can be adjusted to the image
data directly. Here: a linear start from the ray equations, then Levenberg-Marquardt
on the reprojection error, vectorised over frames.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from spotlab.core.errors import ReconstructionError, SpotlabError
from spotlab.geometry import Rig
from spotlab.reconstruction.rigid import check_body_model

__all__ = ["ImagePose", "fit_body_to_images"]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


@dataclass(frozen=True)
class ImagePose:
    """Poses fitted to image points, one per frame.

    Attributes
    ----------
    R : ndarray, shape (F, 3, 3)
        Attitude, ``X = R @ model + t``; NaN where not fitted.
    t : ndarray, shape (F, 3)
        Position (mm); NaN where not fitted.
    rms_px : ndarray, shape (F,)
        RMS image distance between observed and projected markers (px, undistorted
        image scale).
    n_observations : ndarray of int, shape (F,)
        Image points used (marker x camera).
    valid : ndarray of bool, shape (F,)
        At least 3 image points, a well-conditioned normal matrix, and convergence.
    """

    R: FloatArray
    t: FloatArray
    rms_px: FloatArray
    n_observations: NDArray[np.int64]
    valid: BoolArray


def _skew(v: FloatArray) -> FloatArray:
    z = np.zeros(v.shape[:-1])
    x, y, w = v[..., 0], v[..., 1], v[..., 2]
    return np.stack(
        [np.stack([z, -w, y], -1), np.stack([w, z, -x], -1), np.stack([-y, x, z], -1)], -2
    )


class _Scene:
    """Cameras and undistorted observations of one body, arrays over (C, F, P)."""

    def __init__(self, rig: Rig, model: FloatArray, uv: FloatArray) -> None:
        self.Rc = np.stack([c.R for c in rig])  # (C, 3, 3)
        self.tc = np.stack([c.t for c in rig])  # (C, 3)
        self.centers = np.stack([c.center for c in rig])
        self.K2 = np.stack([c.K[:2, :2] for c in rig])
        try:
            self.xn = np.stack([cam.normalize(uv[i]) for i, cam in enumerate(rig)])
        except SpotlabError as exc:
            raise ReconstructionError(f"image points cannot be undistorted: {exc}") from None
        self.seen = np.all(np.isfinite(self.xn), axis=-1)  # (C, F, P)
        self.xn = np.where(self.seen[..., None], self.xn, 0.0)
        self.model = model
        self.m_bar = model.mean(axis=0)

    def residuals(self, R: FloatArray, t: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Pixel-scale residuals (C, F, P, 2) and camera-frame points (C, F, P, 3)."""
        X = np.einsum("fij,pj->fpi", R, self.model) + t[:, None, :]
        xc = np.einsum("cij,fpj->cfpi", self.Rc, X) + self.tc[:, None, None, :]
        z = np.maximum(xc[..., 2:3], 1e-9)
        e = np.einsum("cij,cfpj->cfpi", self.K2, xc[..., :2] / z - self.xn)
        return np.where(self.seen[..., None], e, 0.0), xc

    def normal_equations(self, R: FloatArray, t: FloatArray) -> tuple[FloatArray, FloatArray]:
        """J'J (F, 6, 6) and J'e (F, 6) for a rotation about the body centroid and a shift."""
        e, xc = self.residuals(R, t)
        z = np.maximum(xc[..., 2], 1e-9)
        D = np.zeros((*xc.shape[:-1], 2, 3))
        D[..., 0, 0] = D[..., 1, 1] = 1.0 / z
        D[..., 0, 2] = -xc[..., 0] / z**2
        D[..., 1, 2] = -xc[..., 1] / z**2
        arm = np.einsum("fij,pj->fpi", R, self.model - self.m_bar)
        dX = np.concatenate([-_skew(arm), np.broadcast_to(np.eye(3), (*arm.shape, 3))], -1)
        J = np.einsum("cij,cfpjk,ckl,fplm->cfpim", self.K2, D, self.Rc, dX)
        J = np.where(self.seen[..., None, None], J, 0.0)
        return np.einsum("cfpia,cfpib->fab", J, J), np.einsum("cfpia,cfpi->fa", J, e)

    def linear_start(self) -> tuple[FloatArray, FloatArray, BoolArray]:
        """Pose from the ray equations ``d x (R m + t - c) = 0``, per frame with >= 6 rays."""
        C, F, P = self.seen.shape
        d = np.einsum(
            "cji,cfpj->cfpi", self.Rc, np.concatenate([self.xn, np.ones((C, F, P, 1))], -1)
        )
        d /= np.linalg.norm(d, axis=-1, keepdims=True)
        d = np.where(self.seen[..., None], d, 0.0)
        scale = float(np.sqrt(np.mean(np.sum((self.model - self.m_bar) ** 2, axis=1))))
        mp = (self.model - self.m_bar) / scale
        n_cam = np.any(self.seen, axis=2).sum(axis=0)  # cameras seeing each frame
        w_cam = np.any(self.seen, axis=2).T.astype(float)  # (F, C)
        c_bar = (w_cam @ self.centers) / np.maximum(w_cam.sum(axis=1), 1.0)[:, None]
        # unknowns: s R (row-major, 9) and tau = R m_bar + t - c_bar
        G = np.concatenate(
            [np.kron(np.eye(3), mp[:, None, :]), np.broadcast_to(np.eye(3), (P, 3, 3))], -1
        )
        Sx = _skew(d)  # (C, F, P, 3, 3)
        A = np.einsum("cfpij,pjk->fcpik", Sx, G).reshape(F, C * P * 3, 12)
        rel = self.centers[:, None, :] - c_bar[None, :, :]  # (C, F, 3)
        b = np.einsum("cfpij,cfj->fcpi", Sx, rel).reshape(F, C * P * 3)
        U, S, Vt = np.linalg.svd(A, full_matrices=False)
        Sinv = np.where(S > 1e-12 * S[:, :1], 1.0 / np.where(S > 0, S, 1.0), 0.0)
        x_lsq = np.einsum("fji,fj,fkj,fk->fi", Vt, Sinv, U, b)
        homogeneous = n_cam <= 1
        x = np.where(homogeneous[:, None], Vt[:, -1, :], x_lsq)
        M = x[:, :9].reshape(F, 3, 3)
        M = np.where((np.linalg.det(M) < 0)[:, None, None], -M, M)
        Um, _, Vm = np.linalg.svd(M)
        R = Um @ Vm
        flip = np.linalg.det(R) < 0
        Um[flip, :, 2] *= -1
        R = Um @ Vm
        # position given R: rays through the fitted points (closed form, as in ODLE)
        proj = np.eye(3) - d[..., :, None] * d[..., None, :]
        proj = np.where(self.seen[..., None, None], proj, 0.0)
        target = self.centers[:, None, None, :] - scale * np.einsum("fij,pj->fpi", R, mp)[None]
        N = proj.sum(axis=(0, 2))
        rhs = np.einsum("cfpij,cfpj->fi", proj, target)
        n_obs = self.seen.sum(axis=(0, 2))
        ratio = S[:, -2] / np.maximum(S[:, 0], 1e-300)
        ok = (n_obs >= 6) & np.where(homogeneous, ratio > 1e-6, S[:, -1] > 1e-9 * S[:, 0])
        ok &= np.linalg.cond(np.where(ok[:, None, None], N, np.eye(3))) < 1e12
        pos = np.linalg.solve(np.where(ok[:, None, None], N, np.eye(3)), rhs[..., None])[..., 0]
        t = pos - np.einsum("fij,j->fi", R, self.m_bar)
        return R, t, ok


def _fill(values: FloatArray, ok: BoolArray) -> FloatArray:
    """Copy each frame's nearest earlier good value into the bad frames (later if none)."""
    idx = np.where(ok, np.arange(ok.size), -1)
    idx = np.maximum.accumulate(idx)
    first = int(np.argmax(ok))
    idx = np.where(idx < 0, first, idx)
    return values[idx]


def fit_body_to_images(
    rig: Rig,
    model: Any,
    uv: Any,
    *,
    initial: tuple[Any, Any] | None = None,
    max_iter: int = 50,
    tol: float = 1e-10,
) -> ImagePose:
    """Pose of a rigid body from its image points in any cameras, frame by frame.

    Parameters
    ----------
    rig : Rig
        Calibrated cameras (C of them).
    model : array_like, shape (P, 3)
        Marker coordinates in the body frame (mm), at least 3 non-collinear.
    uv : array_like, shape (C, F, P, 2)
        Image points of each marker in each camera and frame (px), NaN where not seen.
        A marker needs to be seen by one camera only.
    initial : (R, t), optional
        Starting pose, R (3, 3) or (F, 3, 3) and t (3,) or (F, 3). Default: the linear
        solution of each frame with >= 6 image points, copied into frames with fewer.
    max_iter : int
        Levenberg-Marquardt iterations.
    tol : float
        Stop when the relative drop of every frame's cost is below ``tol``.

    Returns
    -------
    ImagePose
        Per-frame pose, RMS image residual (px), observation count and validity.

    Raises
    ------
    ReconstructionError
        Bad shapes, a collinear model, no image point at all, points that cannot be
        undistorted, or no frame with a linear start when ``initial`` is not given.

    Notes
    -----
    Linear start: for a ray from camera centre ``c`` with unit direction ``d``,
    ``d x (R m + t - c) = 0`` is linear in the 12 entries of ``(R, t)``; with >= 6 rays
    (2 equations each) it is solved by least squares (by the null vector when one camera
    sees everything: the scale is then fixed by projecting onto SO(3)), and ``t`` is
    recomputed for the projected ``R`` as the point nearest to the rays. Refinement:
    Levenberg-Marquardt on ``K[:2, :2] (x_proj - x_obs)`` in undistorted normalised
    coordinates (so pixel-scale residuals), rotating about the body centroid. Depth
    along a single camera's line of sight is poorly determined from noisy data
    (Woltring & Huiskes 1990); several cameras help even when each sees other markers.
    """
    if not isinstance(rig, Rig):
        raise ReconstructionError(f"rig must be a Rig, got {type(rig).__name__}")
    m = check_body_model(model)
    obs = np.asarray(uv, dtype=np.float64)
    C, P = len(rig), m.shape[0]
    if obs.ndim != 4 or obs.shape[0] != C or obs.shape[2:] != (P, 2):
        raise ReconstructionError(
            f"uv must have shape ({C}, F, {P}, 2) for {C} cameras and {P} markers, got {obs.shape}"
        )
    if not np.any(np.isfinite(obs)):
        raise ReconstructionError("uv is NaN everywhere: no marker was seen")
    scene = _Scene(rig, m, obs)
    F = obs.shape[1]
    n_obs = scene.seen.sum(axis=(0, 2)).astype(np.int64)
    if initial is None:
        R, t, ok = scene.linear_start()
        if not np.any(ok):
            raise ReconstructionError(
                "no frame has 6 image points in a configuration that gives a linear start; "
                "pass initial=(R, t)"
            )
        R, t = _fill(R, ok), _fill(t, ok)
    else:
        R = np.broadcast_to(np.asarray(initial[0], dtype=np.float64), (F, 3, 3)).copy()
        t = np.broadcast_to(np.asarray(initial[1], dtype=np.float64), (F, 3)).copy()
        if not (np.all(np.isfinite(R)) and np.all(np.isfinite(t))):
            raise ReconstructionError("initial pose holds NaN or infinite values")
    R, t, converged, JtJ = _levenberg_marquardt(scene, R, t, max_iter, tol)
    e, _ = scene.residuals(R, t)
    rms = np.sqrt(np.sum(e**2, axis=(0, 2, 3)) / np.maximum(n_obs, 1))
    ev = np.linalg.eigvalsh(JtJ)
    valid = (n_obs >= 3) & converged & (ev[:, 0] > 1e-12 * np.maximum(ev[:, -1], 1e-300))
    R[~valid] = np.nan
    t[~valid] = np.nan
    return ImagePose(R, t, np.where(valid, rms, np.nan), n_obs, valid)


def _levenberg_marquardt(
    scene: _Scene, R: FloatArray, t: FloatArray, max_iter: int, tol: float
) -> tuple[FloatArray, FloatArray, BoolArray, FloatArray]:
    F = R.shape[0]
    lam = np.full(F, 1e-3)
    cost = np.sum(scene.residuals(R, t)[0] ** 2, axis=(0, 2, 3))
    done = np.zeros(F, dtype=bool)
    for _ in range(max_iter):
        JtJ, Jte = scene.normal_equations(R, t)
        damped = JtJ + lam[:, None, None] * (
            np.diagonal(JtJ, axis1=1, axis2=2)[:, None, :] * np.eye(6) + 1e-9 * np.eye(6)
        )
        step = -np.linalg.solve(damped, Jte[..., None])[..., 0]
        step[done] = 0.0
        dR = Rotation.from_rotvec(step[:, :3]).as_matrix()
        R_new = dR @ R
        centroid = np.einsum("fij,j->fi", R, scene.m_bar) + t
        t_new = centroid + step[:, 3:] - np.einsum("fij,j->fi", R_new, scene.m_bar)
        new_cost = np.sum(scene.residuals(R_new, t_new)[0] ** 2, axis=(0, 2, 3))
        better = (new_cost <= cost) & ~done
        small = better & (cost - new_cost <= tol * np.maximum(cost, 1e-300))
        R = np.where(better[:, None, None], R_new, R)
        t = np.where(better[:, None], t_new, t)
        cost = np.where(better, new_cost, cost)
        lam = np.where(better, lam / 3.0, lam * 5.0)
        done |= small | (lam > 1e12)
        if np.all(done):
            break
    JtJ, _ = scene.normal_equations(R, t)
    return R, t, done, JtJ
