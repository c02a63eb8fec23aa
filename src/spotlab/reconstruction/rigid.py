"""Rigid-body pose from marker coordinates: SVD least squares, weights, missing markers.

Spoor & Veldpaus (1980) and Veldpaus et al. (1988) as summarised by Woltring &
Huiskes (1990) Eq. 9-10; the rotation by the singular value decomposition of the
weighted cross-covariance with the determinant (reflection) guard of Arun et al.
(1987) and Umeyama (1991). Vectorised over frames: one batched SVD for all of them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from spotlab.core.errors import ReconstructionError

__all__ = ["RigidPose", "check_body_model", "kabsch", "rigid_fit", "rigid_pose"]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

#: Markers whose spread across their main line is below this fraction of the spread
#: along it count as collinear (the rotation about that line is then undetermined).
COLLINEAR_TOL = 1e-6


@dataclass(frozen=True)
class RigidPose:
    """Poses of a rigid body, one per frame, with their quality figures.

    Attributes
    ----------
    R : ndarray, shape (F, 3, 3)
        Attitude: ``observed ≈ R @ model + t``; NaN where the frame could not be fitted.
    t : ndarray, shape (F, 3)
        Position of the body origin (mm); NaN where the frame could not be fitted.
    rms : ndarray, shape (F,)
        Weighted RMS distance between fitted and observed markers (mm).
    residuals : ndarray, shape (F, P)
        Distance of each observed marker from its fitted position (mm); NaN where the
        marker is missing or the frame was not fitted.
    n_visible : ndarray of int, shape (F,)
        Markers with a finite observation and a positive weight.
    valid : ndarray of bool, shape (F,)
        The frame was fitted.
    collinear : ndarray of bool, shape (F,)
        The frame had >= 3 visible markers, but they (or their observations) were
        collinear: the rotation about their line is undetermined and the pose is NaN.
    """

    R: FloatArray
    t: FloatArray
    rms: FloatArray
    residuals: FloatArray
    n_visible: NDArray[np.int64]
    valid: BoolArray
    collinear: BoolArray


def check_body_model(model: Any) -> FloatArray:
    """Validate a body model: shape (P, 3), P >= 3, finite, not collinear.

    Parameters
    ----------
    model : array_like, shape (P, 3)
        Marker coordinates in the body frame (mm).

    Returns
    -------
    ndarray, shape (P, 3)
        A float64 copy.

    Raises
    ------
    ReconstructionError
        Wrong shape, fewer than 3 markers, NaN, or collinear markers.
    """
    try:
        m = np.array(model, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ReconstructionError(f"model must be numeric marker coordinates: {exc}") from None
    if m.ndim != 2 or m.shape[1] != 3:
        raise ReconstructionError(f"model must have shape (P, 3), got {m.shape}")
    if m.shape[0] < 3:
        raise ReconstructionError(
            f"model has {m.shape[0]} markers: a rigid body needs at least 3 non-collinear"
        )
    if not np.all(np.isfinite(m)):
        raise ReconstructionError("model holds NaN or infinite marker coordinates")
    s = np.linalg.svd(m - m.mean(axis=0), compute_uv=False)
    if not s[1] > COLLINEAR_TOL * s[0]:
        raise ReconstructionError(
            "model markers are collinear (or coincide): the rotation about their line "
            "is undetermined; a rigid body needs at least 3 non-collinear markers"
        )
    return m


def _observations(observed: Any, n_markers: int) -> FloatArray:
    try:
        obs = np.array(observed, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ReconstructionError(f"observed must be numeric coordinates: {exc}") from None
    if obs.ndim != 3 or obs.shape[1:] != (n_markers, 3):
        raise ReconstructionError(
            f"observed must have shape (F, {n_markers}, 3) to match the model, got {obs.shape}"
        )
    if obs.shape[0] == 0:
        raise ReconstructionError("observed holds no frames")
    if np.any(np.isinf(obs)):
        raise ReconstructionError("observed holds infinite values (use NaN for missing)")
    if not np.any(np.isfinite(obs)):
        raise ReconstructionError("observed is NaN everywhere: no marker was seen")
    return obs


def _weights(weights: Any, shape: tuple[int, int]) -> FloatArray:
    if weights is None:
        return np.ones(shape)
    w = np.asarray(weights, dtype=np.float64)
    if w.shape not in (shape[1:], shape):
        raise ReconstructionError(
            f"weights must have shape ({shape[1]},) or {shape}, got {w.shape}"
        )
    if not np.all(np.isfinite(w)) or np.any(w < 0.0):
        raise ReconstructionError("weights must be finite and >= 0")
    return np.broadcast_to(w, shape).astype(np.float64)


def rigid_pose(model: Any, observed: Any, weights: Any = None) -> RigidPose:
    r"""Least-squares pose of a rigid body in every frame, with quality figures.

    Parameters
    ----------
    model : array_like, shape (P, 3)
        Marker coordinates in the body frame (mm), at least 3 non-collinear.
    observed : array_like, shape (F, P, 3)
        Observed marker coordinates per frame (mm), NaN where a marker is missing.
    weights : array_like, shape (P,) or (F, P), optional
        Non-negative weight of each marker (e.g. inverse variance); default 1.

    Returns
    -------
    RigidPose
        ``R``, ``t``, ``rms`` and per-marker residuals; frames with fewer than 3
        visible markers, or with collinear ones, have a NaN pose and ``valid`` false.

    Raises
    ------
    ReconstructionError
        Bad shapes, a collinear model, infinite values, negative weights, or
        ``observed`` NaN everywhere.

    Notes
    -----
    Per frame, with the visible markers' weights :math:`w_i`, weighted centroids
    :math:`\bar m, \bar o` and :math:`H = \sum_i w_i (m_i - \bar m)(o_i - \bar o)^T
    = U S V^T`, the rotation minimising :math:`\sum_i w_i |R m_i + t - o_i|^2` is
    :math:`R = V \operatorname{diag}(1, 1, d) U^T`, :math:`d = \operatorname{sign}\det
    (V U^T)`, and :math:`t = \bar o - R \bar m` (Woltring & Huiskes 1990 Eq. 9-10).
    The factor ``d`` keeps ``R`` a rotation when noise would make the best orthogonal
    matrix a reflection. The pose is unique when ``S[1] > 0``: at least 3 visible
    markers, not collinear in either frame.
    """
    m = check_body_model(model)
    obs = _observations(observed, m.shape[0])
    F, P = obs.shape[:2]
    w = _weights(weights, (F, P))
    seen = np.all(np.isfinite(obs), axis=2) & (w > 0.0)
    w = np.where(seen, w, 0.0)
    n_visible = seen.sum(axis=1).astype(np.int64)
    enough = n_visible >= 3
    wsum = np.where(enough, w.sum(axis=1), 1.0)
    o = np.where(seen[..., None], obs, 0.0)
    m_bar = (w @ m) / wsum[:, None]
    o_bar = np.einsum("fp,fpk->fk", w, o) / wsum[:, None]
    dm = m[None, :, :] - m_bar[:, None, :]
    do = o - o_bar[:, None, :]
    H = np.einsum("fp,fpi,fpj->fij", w, dm, do)
    U, S, Vt = np.linalg.svd(H)
    collinear = enough & ~(S[:, 1] > COLLINEAR_TOL**2 * S[:, 0])
    valid = enough & ~collinear
    V = np.swapaxes(Vt, 1, 2)
    d = np.sign(np.linalg.det(V @ np.swapaxes(U, 1, 2)))
    d = np.where(d == 0.0, 1.0, d)
    V[:, :, 2] *= d[:, None]
    R = V @ np.swapaxes(U, 1, 2)
    t = o_bar - np.einsum("fij,fj->fi", R, m_bar)
    R[~valid] = np.nan
    t[~valid] = np.nan
    fitted = np.einsum("fij,pj->fpi", R, m) + t[:, None, :]
    residuals = np.where(seen, np.linalg.norm(fitted - obs, axis=2), np.nan)
    rms = np.sqrt(np.nansum(w * np.where(seen, residuals, 0.0) ** 2, axis=1) / wsum)
    rms = np.where(valid, rms, np.nan)
    residuals[~valid] = np.nan
    return RigidPose(R, t, rms, residuals, n_visible, valid, collinear)


def rigid_fit(
    model: Any, observed: Any, weights: Any = None
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Least-squares rotation and translation of a rigid body, frame by frame.

    Parameters
    ----------
    model : array_like, shape (P, 3)
        Marker coordinates in the body frame (mm), at least 3 non-collinear.
    observed : array_like, shape (F, P, 3)
        Observed marker coordinates (mm), NaN where a marker is missing.
    weights : array_like, shape (P,) or (F, P), optional
        Non-negative weight of each marker; default 1.

    Returns
    -------
    R : ndarray, shape (F, 3, 3)
        Rotations with ``observed ≈ R @ model + t``, det +1.
    t : ndarray, shape (F, 3)
        Translations (mm).
    rms : ndarray, shape (F,)
        Weighted RMS marker distance after the fit (mm).

    Frames with fewer than 3 visible non-collinear markers get NaN in all three; use
    :func:`rigid_pose` for the per-frame flags and residuals.

    Raises
    ------
    ReconstructionError
        See :func:`rigid_pose`.

    Examples
    --------
    >>> import numpy as np
    >>> model = np.array([[0.0, 0, 0], [100, 0, 0], [0, 50, 0], [0, 0, 30]])
    >>> Rz = np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]])
    >>> observed = (model @ Rz.T + [10.0, 20, 30])[None]
    >>> R, t, rms = rigid_fit(model, observed)
    >>> bool(np.allclose(R[0], Rz)), t[0].round(6).tolist(), bool(rms[0] < 1e-9)
    (True, [10.0, 20.0, 30.0], True)
    """
    pose = rigid_pose(model, observed, weights)
    return pose.R, pose.t, pose.rms


def kabsch(model: FloatArray, observed: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Least-squares rotation (3, 3) and translation (3,), ``observed ~ R @ model + t``,
    of matched points (P, 3) mm of one frame, all seen, P >= 3 not collinear.

    The solution of :func:`rigid_pose` (its Notes) for one frame with equal weights,
    without its checks: for loops that call it every frame on points they have checked.
    """
    a, b = model.mean(axis=0), observed.mean(axis=0)
    U, _, Vt = np.linalg.svd((model - a).T @ (observed - b))
    if np.linalg.det(Vt.T @ U.T) < 0:
        Vt[-1] *= -1.0
    R = Vt.T @ U.T
    return R, b - R @ a
