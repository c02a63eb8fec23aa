"""Intrinsics from vanishing points of orthogonal directions (image of the absolute conic).

Pribanić, Sturm & Cifrek (2005): the vanishing points ``v1``, ``v2`` of two orthogonal
3-D directions satisfy ``v1' omega v2 = 0`` (their Eq. 7), linear in the image of the
absolute conic ``omega = (K K')^-1 = K^-T K^-1`` (Eq. 5). An orthogonal triad waved
through the volume gives three such pairs per frame; least squares over many frames
gives ``omega``, and its Cholesky factor gives ``K``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from spotlab.core.errors import CalibrationError

__all__ = ["IacResult", "intrinsics_from_orthogonal_vanishing_points"]

FloatArray = NDArray[np.float64]

Assumption = Literal["none", "zero_skew", "square_pixels"]

#: Unknowns of omega kept under each assumption, as (row, col) of the upper triangle.
_UNKNOWNS: dict[str, tuple[tuple[int, int], ...]] = {
    "none": ((0, 0), (0, 1), (1, 1), (0, 2), (1, 2), (2, 2)),
    "zero_skew": ((0, 0), (1, 1), (0, 2), (1, 2), (2, 2)),
    "square_pixels": ((0, 0), (0, 2), (1, 2), (2, 2)),  # omega_11 = omega_00, omega_01 = 0
}

#: A second-smallest singular value below this fraction of the largest: not determined.
_RANK_TOL = 1e-9


@dataclass(frozen=True)
class IacResult:
    """Outcome of :func:`intrinsics_from_orthogonal_vanishing_points`.

    Attributes
    ----------
    K : ndarray, shape (3, 3)
        Intrinsic matrix ``[[fx, s, cx], [0, fy, cy], [0, 0, 1]]`` (px).
    omega : ndarray, shape (3, 3)
        The image of the absolute conic ``K^-T K^-1`` (scaled so ``omega[2, 2] = 1``
        after the conditioning is undone; only its direction is determined).
    angle_error_deg : ndarray, shape (N,)
        Per used pair, how far the angle between the two directions implied by ``K``
        (Eq. 6 of Pribanić et al.) is from 90 degrees (>= 0).
    rms_angle_error_deg : float
        Root mean square of ``angle_error_deg``.
    n_pairs : int
        Pairs used (pairs holding NaN are left out).
    condition : float
        Ratio of the smallest significant to the largest singular value of the
        (conditioned) constraint matrix: near 0 means the pairs barely determine omega.
    assume : str
        The assumption the fit was made under.
    """

    K: FloatArray
    omega: FloatArray
    angle_error_deg: FloatArray
    rms_angle_error_deg: float
    n_pairs: int
    condition: float
    assume: str


def _homogeneous(v: Any, what: str) -> FloatArray:
    arr = np.asarray(v, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] not in (2, 3):
        raise CalibrationError(
            f"{what} must have shape (N, 3) (homogeneous) or (N, 2) (px), got {arr.shape}"
        )
    if arr.shape[1] == 2:
        arr = np.column_stack([arr, np.ones(arr.shape[0])])
    return arr


def _conditioning(v1: FloatArray, v2: FloatArray, image_size: Any) -> FloatArray:
    """Similarity T (3, 3) taking the image to a unit-sized frame centred on it."""
    if image_size is not None:
        w, h = (float(x) for x in image_size)
        if not (w > 0.0 and h > 0.0):
            raise CalibrationError(f"image_size must be positive (width, height), got {image_size}")
        centre, scale = np.array([w / 2.0, h / 2.0]), 2.0 / np.hypot(w, h)
    else:
        v = np.concatenate([v1, v2])
        finite = np.abs(v[:, 2]) > 1e-3 * np.linalg.norm(v, axis=1)
        if np.count_nonzero(finite) < 2:
            raise CalibrationError(
                "image_size is needed: fewer than two vanishing points are finite"
            )
        xy = v[finite, :2] / v[finite, 2:3]
        centre = np.median(xy, axis=0)
        scale = 1.0 / float(np.median(np.linalg.norm(xy - centre, axis=1)) + 1e-300)
    T = np.diag([scale, scale, 1.0])
    T[:2, 2] = -scale * centre
    return T


def _angle_errors(omega: FloatArray, v1: FloatArray, v2: FloatArray) -> FloatArray:
    q12 = np.einsum("ni,ij,nj->n", v1, omega, v2)
    q11 = np.einsum("ni,ij,nj->n", v1, omega, v1)
    q22 = np.einsum("ni,ij,nj->n", v2, omega, v2)
    cos = np.clip(np.abs(q12) / np.sqrt(q11 * q22), 0.0, 1.0)
    return np.asarray(np.degrees(np.arcsin(cos)))


def intrinsics_from_orthogonal_vanishing_points(
    v1: Any,
    v2: Any,
    *,
    assume: Assumption = "none",
    image_size: tuple[float, float] | None = None,
) -> IacResult:
    """Intrinsic matrix from vanishing points of pairs of orthogonal directions.

    Parameters
    ----------
    v1, v2 : array_like, shape (N, 3) or (N, 2)
        Vanishing points of the two directions of each orthogonal pair: homogeneous
        (as :func:`vanishing_point` returns them, points at infinity allowed) or in px.
        Distortion must have been removed from the image data. Pairs holding NaN are
        left out. For an orthogonal triad seen in one frame, the three pairs are
        (x, y), (x, z) and (y, z).
    assume : {"none", "zero_skew", "square_pixels"}
        What is known of ``K``. ``"none"``: general ``K`` with skew, 5 unknowns, needs
        >= 5 pairs from >= 2 triad attitudes. ``"zero_skew"``: 4 unknowns, >= 4 pairs.
        ``"square_pixels"``: zero skew and ``fx = fy``, 3 unknowns, >= 3 pairs (one
        triad attitude suffices if none of its vanishing points is at infinity).
    image_size : (width, height), optional
        Image size (px), used only to condition the linear system (centre and scale of
        the image). Without it, the median of the finite vanishing points is used.

    Returns
    -------
    IacResult
        ``K``, ``omega``, the per-pair angle errors and how well the pairs determine
        ``omega``.

    Raises
    ------
    CalibrationError
        Too few pairs for the assumption; pairs that do not determine ``omega`` (all
        from one attitude of the triad, or otherwise degenerate); an ``omega`` that is
        not positive definite (too much noise, pairs that are not orthogonal, or
        distortion not removed); mismatched or malformed input.

    Notes
    -----
    With ``omega`` symmetric, ``v1' omega v2 = 0`` is one linear equation in its six
    entries ``(w00, w01, w11, w02, w12, w22)`` with coefficients ``(a0 b0, a0 b1 + a1 b0,
    a1 b1, a0 b2 + a2 b0, a1 b2 + a2 b1, a2 b2)``. Zero skew means ``w01 = 0``; square
    pixels also ``w11 = w00`` (Hartley & Zisserman 2004, Sec. 8.8). The points are first
    conditioned by a similarity ``T`` (``v -> T v``, which keeps zero skew and square
    pixels), each equation is scaled to unit norm, and the unit vector minimising the
    residual is the right singular vector of the smallest singular value; a second
    singular value below 1e-9 of the largest means the pairs do not determine ``omega``.
    ``omega`` is then turned positive (trace > 0), checked positive definite, and factored
    ``omega = U' U`` (Cholesky, ``U`` upper triangular); ``K = T^-1 U^-1`` scaled to
    ``K[2, 2] = 1``. Pribanić, Sturm & Cifrek (2005), Eq. 5-7.
    """
    if assume not in _UNKNOWNS:
        raise CalibrationError(f"assume must be one of {sorted(_UNKNOWNS)}, got {assume!r}")
    a = _homogeneous(v1, "v1")
    b = _homogeneous(v2, "v2")
    if a.shape != b.shape:
        raise CalibrationError(f"v1 {a.shape} and v2 {b.shape} must hold the same pairs")
    keep = np.all(np.isfinite(a), axis=1) & np.all(np.isfinite(b), axis=1)
    keep &= (np.linalg.norm(a, axis=1) > 0.0) & (np.linalg.norm(b, axis=1) > 0.0)
    a, b = a[keep], b[keep]
    unknowns = _UNKNOWNS[assume]
    needed = len(unknowns) - 1
    if a.shape[0] < needed:
        raise CalibrationError(
            f"too few orthogonal pairs: assume={assume!r} needs at least {needed}, got "
            f"{a.shape[0]} usable (of {keep.size})"
        )
    T = _conditioning(a, b, image_size)
    an = a @ T.T
    bn = b @ T.T
    an /= np.linalg.norm(an, axis=1, keepdims=True)
    bn /= np.linalg.norm(bn, axis=1, keepdims=True)
    # Coefficient of omega[i, j] (i <= j) in a' omega b.
    full = {
        (i, j): an[:, i] * bn[:, j] + (an[:, j] * bn[:, i] if i != j else 0.0)
        for i in range(3)
        for j in range(i, 3)
    }
    columns = [full[ij] for ij in unknowns]
    if assume == "square_pixels":
        columns[0] = full[(0, 0)] + full[(1, 1)]
    A = np.column_stack(columns)
    A /= np.linalg.norm(A, axis=1, keepdims=True)
    if A.shape[0] < A.shape[1]:  # the minimal case: pad so the null vector is the last row
        A = np.vstack([A, np.zeros((A.shape[1] - A.shape[0], A.shape[1]))])
    _, sv, vt = np.linalg.svd(A, full_matrices=False)
    condition = float(sv[-2] / sv[0])
    if condition < _RANK_TOL:
        raise CalibrationError(
            "the orthogonal pairs do not determine omega (degenerate: all pairs from one "
            "attitude of the triad, or parallel directions); move the triad through "
            f"several attitudes (singular values {np.array2string(sv, precision=3)})"
        )
    x = vt[-1]
    values = dict(zip(unknowns, x, strict=True))
    if assume == "square_pixels":
        values[(1, 1)] = values[(0, 0)]
    omega_n = np.zeros((3, 3))
    for (i, j), val in values.items():
        omega_n[i, j] = omega_n[j, i] = val
    if np.trace(omega_n) < 0.0:
        omega_n = -omega_n
    eig = np.linalg.eigvalsh(omega_n)
    if not eig[0] > 0.0:
        raise CalibrationError(
            "omega (image of the absolute conic) is not positive definite (eigenvalues "
            f"{np.array2string(eig, precision=3)}): too much noise in the vanishing points, "
            "pairs that are not orthogonal, or lens distortion not removed"
        )
    U = np.linalg.cholesky(omega_n).T
    K: FloatArray = np.asarray(np.linalg.solve(T, np.linalg.inv(U)), dtype=np.float64)
    K /= K[2, 2]
    K[1, 0] = K[2, 0] = K[2, 1] = 0.0
    if assume != "none":
        K[0, 1] = 0.0
    Kinv = np.linalg.inv(K)
    omega = Kinv.T @ Kinv
    omega /= omega[2, 2]
    errors = _angle_errors(omega, a, b)
    return IacResult(
        K=K,
        omega=omega,
        angle_error_deg=errors,
        rms_angle_error_deg=float(np.sqrt(np.mean(errors**2))),
        n_pairs=int(a.shape[0]),
        condition=condition,
        assume=assume,
    )
