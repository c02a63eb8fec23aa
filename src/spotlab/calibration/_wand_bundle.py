"""Bundle adjustment of a wand dance: Levenberg-Marquardt with the Schur complement.

Unknowns: one 15-parameter block per camera (see ``_camera_block``) and, per wand frame,
the wand's centre (3, mm) and direction (2, a tangent increment of a unit vector); the
wand length is known, so each frame has 5 degrees of freedom and the metric scale is
fixed. Static reference points with known world coordinates (the L-frame or triad) add
residuals on the camera blocks only and fix the world frame.

The normal equations have the block-arrow structure of every bundle adjustment: the
frame blocks are 5x5 and independent, so they are eliminated exactly (Schur complement)
and only the dense ``15 C x 15 C`` reduced camera system is factored. One iteration of
8 cameras x 3000 frames costs a few tens of milliseconds, where a general sparse solver
(scipy's ``least_squares`` with ``jac_sparsity``) takes seconds per iteration on the same
problem. Robustness: Huber weights on each image point's residual norm (iteratively
re-weighted), and observations beyond a multiple of the robust residual scale can be
rejected between runs.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import cho_factor, cho_solve

from spotlab.calibration._camera_block import (
    BLOCK,
    project,
    project_with_jacobians,
    rotate_blocks,
)

__all__ = [
    "BundleProblem",
    "BundleState",
    "adjust",
    "huber_weights",
    "reduced_camera_system",
    "robust_cost",
    "robust_sigma",
]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


@dataclass
class BundleState:
    """Current estimate: camera blocks, rotations, wand centres and directions."""

    blocks: FloatArray  # (C, 15)
    rotations: FloatArray  # (C, 3, 3)
    centres: FloatArray  # (F, 3) mm
    directions: FloatArray  # (F, 3) unit

    def copy(self) -> BundleState:
        return BundleState(
            self.blocks.copy(), self.rotations.copy(), self.centres.copy(), self.directions.copy()
        )

    def wand_ends(self, length: float) -> FloatArray:
        """Both wand ends, shape (F, 2, 3) (mm)."""
        half = 0.5 * length * self.directions
        return np.stack([self.centres - half, self.centres + half], axis=1)


@dataclass
class BundleProblem:
    """Observations and settings of one adjustment.

    Attributes
    ----------
    wand_uv : ndarray, shape (F, C, 2, 2)
        Wand-end image points (px); NaN where unseen.
    wand_length : float
        Known wand length (mm).
    frame_uv : ndarray, shape (C, P, 2)
        Image points of the static reference object (px); NaN where unseen.
    frame_points : ndarray, shape (P, 3)
        Its world coordinates (mm).
    free : ndarray of bool, shape (C, 15)
        Which block parameters are adjusted.
    huber_px : float
        Residual norm (px) beyond which an observation's weight falls as 1/|r|.
    use : ndarray of bool, shape (F, C, 2)
        Wand observations taking part (outliers removed are False).
    frame_weight : float
        Weight of a reference-object residual relative to a wand residual.
    """

    wand_uv: FloatArray
    wand_length: float
    frame_uv: FloatArray
    frame_points: FloatArray
    free: BoolArray
    huber_px: float = 1.0
    use: BoolArray = field(default_factory=lambda: np.zeros((0, 0, 2), dtype=bool))
    frame_weight: float = 1.0

    def __post_init__(self) -> None:
        seen = np.all(np.isfinite(self.wand_uv), axis=-1)
        self.use = seen if self.use.shape != seen.shape else self.use & seen


def robust_sigma(r: FloatArray) -> float:
    """Robust scale (px) of 2-D residuals: the median norm of a circular normal is 1.1774 sigma."""
    norm = np.linalg.norm(r, axis=-1)
    norm = norm[np.isfinite(norm)]
    return float(np.median(norm) / 1.1774) if norm.size else np.nan


def huber_weights(norm: FloatArray, k: float) -> FloatArray:
    """IRLS weights of Huber's loss on residual norms: 1 inside ``k``, ``k/|r|`` beyond."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(norm <= k, 1.0, k / norm)


def _huber_cost(norm: FloatArray, k: float) -> float:
    return float(np.sum(np.where(norm <= k, norm * norm, 2.0 * k * norm - k * k)))


def _tangent_basis(d: FloatArray) -> FloatArray:
    """Orthonormal bases (F, 3, 2) of the planes perpendicular to unit vectors d (F, 3)."""
    a = np.where(np.abs(d[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    b1 = np.cross(d, a)
    b1 /= np.linalg.norm(b1, axis=1, keepdims=True)
    b2 = np.cross(d, b1)
    return np.stack([b1, b2], axis=2)


def _grid(F: int, C: int) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.intp]]:
    f, c, e = np.meshgrid(np.arange(F), np.arange(C), np.arange(2), indexing="ij")
    return f.ravel(), c.ravel(), e.ravel()


def residuals(problem: BundleProblem, state: BundleState) -> tuple[FloatArray, FloatArray]:
    """Wand residuals (F, C, 2, 2) and frame residuals (C, P, 2) in px (NaN where unused)."""
    F, C = problem.wand_uv.shape[:2]
    f, c, e = _grid(F, C)
    X = state.wand_ends(problem.wand_length)[f, e]
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = project(state.blocks, state.rotations, c, X).reshape(F, C, 2, 2)
    r = np.where(problem.use[..., None], uv - problem.wand_uv, np.nan)
    P = problem.frame_points.shape[0]
    cc, pp = np.meshgrid(np.arange(C), np.arange(P), indexing="ij")
    with np.errstate(divide="ignore", invalid="ignore"):
        fuv = project(state.blocks, state.rotations, cc.ravel(), problem.frame_points[pp.ravel()])
    return r, fuv.reshape(C, P, 2) - problem.frame_uv


def robust_cost(problem: BundleProblem, state: BundleState) -> float:
    """Huber cost (px^2) of the wand and (weighted) reference-object residuals."""
    r, fr = residuals(problem, state)
    norm = np.linalg.norm(r, axis=-1)
    fnorm = np.linalg.norm(fr, axis=-1)
    wand = _huber_cost(norm[problem.use], problem.huber_px)
    fseen = np.isfinite(fnorm)
    frame = problem.frame_weight * _huber_cost(fnorm[fseen], problem.huber_px)
    total = wand + frame
    return total if np.isfinite(total) else np.inf


def _normal_equations(
    problem: BundleProblem, state: BundleState
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """U (C,15,15), W (F,C,15,5), V (F,5,5), g_b (C,15), g_f (F,5), tangent bases (F,3,2)."""
    F, C = problem.wand_uv.shape[:2]
    f, c, e = _grid(F, C)
    L = problem.wand_length
    X = state.wand_ends(L)[f, e]
    with np.errstate(divide="ignore", invalid="ignore"):
        uv, d_block, d_point, _ = project_with_jacobians(state.blocks, state.rotations, c, X)
    use = problem.use.ravel()
    r = np.where(use[:, None], uv - problem.wand_uv.reshape(-1, 2), 0.0)
    w = np.where(use, huber_weights(np.linalg.norm(r, axis=1), problem.huber_px), 0.0)
    sw = np.sqrt(w)[:, None, None]
    d_block = np.where(use[:, None, None], d_block, 0.0) * sw
    d_point = np.where(use[:, None, None], d_point, 0.0) * sw
    r = r * sw[:, :, 0]
    basis = _tangent_basis(state.directions)
    sign = np.where(e == 0, -0.5 * L, 0.5 * L)
    d_dir = np.einsum("nij,njk->nik", d_point, basis[f]) * sign[:, None, None]
    d_frame = np.concatenate([d_point, d_dir], axis=2)  # (n, 2, 5)

    jb = d_block.reshape(F, C, 4, BLOCK)
    jf = d_frame.reshape(F, C, 4, 5)
    rr = r.reshape(F, C, 4)
    U = np.einsum("fcrp,fcrq->cpq", jb, jb)
    W = np.einsum("fcrp,fcrq->fcpq", jb, jf)
    V = np.einsum("fcrp,fcrq->fpq", jf, jf)
    g_b = np.einsum("fcrp,fcr->cp", jb, rr)
    g_f = np.einsum("fcrp,fcr->fp", jf, rr)

    # The static reference object: known points, camera blocks only.
    P = problem.frame_points.shape[0]
    cgrid, pgrid = np.meshgrid(np.arange(C), np.arange(P), indexing="ij")
    cc, pp = cgrid.ravel(), pgrid.ravel()
    fuv = problem.frame_uv.reshape(-1, 2)
    seen = np.all(np.isfinite(fuv), axis=1)
    if np.any(seen):
        with np.errstate(divide="ignore", invalid="ignore"):
            puv, pjb, _, _ = project_with_jacobians(
                state.blocks, state.rotations, cc[seen], problem.frame_points[pp[seen]]
            )
        fr = puv - fuv[seen]
        fw = problem.frame_weight * huber_weights(np.linalg.norm(fr, axis=1), problem.huber_px)
        pjb = pjb * np.sqrt(fw)[:, None, None]
        fr = fr * np.sqrt(fw)[:, None]
        np.add.at(U, cc[seen], np.einsum("nrp,nrq->npq", pjb, pjb))
        np.add.at(g_b, cc[seen], np.einsum("nrp,nr->np", pjb, fr))
    return U, W, V, g_b, g_f, basis


def reduced_camera_system(
    problem: BundleProblem, state: BundleState
) -> tuple[FloatArray, FloatArray]:
    """The camera block of the normal equations with the wand frames eliminated (Schur).

    Returns
    -------
    S : ndarray, shape (15 C, 15 C)
        ``J'J`` of the (Huber-weighted) reprojection residuals with respect to every
        camera parameter, all frame unknowns marginalised: ``U - W V^-1 W'``. Its
        inverse, restricted to the adjusted parameters, is their covariance in units of
        the image-point variance (px^2).
    g : ndarray, shape (15 C,)
        The reduced gradient ``J'r`` (px), frames marginalised: a Gauss-Newton step of
        the adjusted parameters is ``-S^-1 g`` restricted to them.
    """
    U, W, V, g_b, g_f, _ = _normal_equations(problem, state)
    F, C = W.shape[:2]
    Vinv = np.linalg.pinv(V)
    Y = np.einsum("fcpq,fqs->fcps", W, Vinv)
    n = C * BLOCK
    Ym = Y.transpose(1, 2, 0, 3).reshape(n, F * 5)
    S = -(Ym @ W.transpose(1, 2, 0, 3).reshape(n, F * 5).T)
    for c in range(C):
        S[c * BLOCK : (c + 1) * BLOCK, c * BLOCK : (c + 1) * BLOCK] += U[c]
    g = g_b.ravel() - Ym @ g_f.ravel()
    return 0.5 * (S + S.T), g


@dataclass
class AdjustmentLog:
    """What one run of :func:`adjust` did."""

    iterations: int = 0
    initial_cost: float = np.nan
    final_cost: float = np.nan
    converged: bool = False


def _step(
    problem: BundleProblem,
    U: FloatArray,
    W: FloatArray,
    V: FloatArray,
    g_b: FloatArray,
    g_f: FloatArray,
    lam: float,
) -> tuple[FloatArray, FloatArray] | None:
    """Damped Gauss-Newton step (camera blocks (C,15), frames (F,5)); None if singular."""
    F, C = W.shape[:2]
    free = problem.free.astype(np.float64)
    # Fixed parameters: zero their rows and columns, unit diagonal (their step is 0).
    Uf = U * free[:, :, None] * free[:, None, :]
    Wf = W * free[None, :, :, None]
    gbf = g_b * free
    diag_u = np.einsum("cpp->cp", Uf)
    scale_u = np.maximum(diag_u, 1e-9 * (diag_u.max() + 1e-300))
    Uf = Uf + np.einsum("cp,pq->cpq", lam * scale_u * free + (1.0 - free), np.eye(BLOCK))
    diag_v = np.einsum("fpp->fp", V)
    Vd = V + np.einsum("fp,pq->fpq", lam * np.maximum(diag_v, 1e-12), np.eye(5))
    try:
        Vinv = np.linalg.inv(Vd)
    except np.linalg.LinAlgError:
        return None
    Y = np.einsum("fcpq,fqs->fcps", Wf, Vinv)  # W V^-1
    n = C * BLOCK
    Ym = Y.transpose(1, 2, 0, 3).reshape(n, F * 5)
    Wm = Wf.transpose(1, 2, 0, 3).reshape(n, F * 5)
    S = -(Ym @ Wm.T)
    for c in range(C):
        S[c * BLOCK : (c + 1) * BLOCK, c * BLOCK : (c + 1) * BLOCK] += Uf[c]
    rhs = -gbf.ravel() + Ym @ g_f.ravel()
    try:
        db = cho_solve(cho_factor(S), rhs)
    except np.linalg.LinAlgError:
        return None
    db = db.reshape(C, BLOCK) * free
    df = np.einsum("fpq,fq->fp", Vinv, -g_f - np.einsum("fcpq,cp->fq", Wf, db))
    return db, df


def _apply(state: BundleState, db: FloatArray, df: FloatArray, basis: FloatArray) -> BundleState:
    blocks, rotations = rotate_blocks(state.blocks + db, state.rotations)
    centres = state.centres + df[:, 0:3]
    directions = state.directions + np.einsum("fij,fj->fi", basis, df[:, 3:5])
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    return BundleState(blocks, rotations, centres, directions)


def adjust(
    problem: BundleProblem,
    state: BundleState,
    *,
    max_iterations: int = 50,
    tolerance: float = 1e-10,
) -> tuple[BundleState, AdjustmentLog]:
    """Minimise the robust reprojection cost from ``state``.

    Returns the adjusted state and a log; stops when the relative cost decrease of an
    accepted step falls below ``tolerance`` or after ``max_iterations`` linearisations.
    """
    log = AdjustmentLog(initial_cost=robust_cost(problem, state))
    cost = log.initial_cost
    lam = 1e-3
    for it in range(max_iterations):
        U, W, V, g_b, g_f, basis = _normal_equations(problem, state)
        log.iterations = it + 1
        improved = False
        for _ in range(12):
            step = _step(problem, U, W, V, g_b, g_f, lam)
            if step is not None:
                trial = _apply(state, *step, basis)
                trial_cost = robust_cost(problem, trial)
                if trial_cost < cost:
                    improved = True
                    break
            lam *= 10.0
        if not improved:
            log.converged = True
            break
        decrease = (cost - trial_cost) / max(cost, 1e-300)
        state, cost = trial, trial_cost
        lam = max(lam / 10.0, 1e-9)
        if decrease < tolerance:
            log.converged = True
            break
    log.final_cost = cost
    return state, log
