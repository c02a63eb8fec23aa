"""DLT calibration of one camera from >= 6 non-coplanar control points (Woltring Eq. 13-15).

A Hartley-normalised linear solve gives the 11 DLT parameters; they are turned into a
camera (RQ decomposition) whose parameters are then adjusted by non-linear least squares
on the image residuals, optionally with Brown distortion terms (Marzan & Karara 1975).
Also the plane-constrained single-camera reconstruction of Woltring Eq. 2-3.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from spotlab.core.errors import CalibrationError
from spotlab.geometry import Camera, distort_normalized

__all__ = ["DISTORTION_TERMS", "DltResult", "dlt_calibrate", "dlt_reconstruct_on_plane"]

FloatArray = NDArray[np.float64]

#: Names of the distortion terms, in OpenCV's order.
DISTORTION_TERMS = ("k1", "k2", "p1", "p2", "k3")


@dataclass(frozen=True)
class DltResult:
    """Outcome of :func:`dlt_calibrate`.

    Attributes
    ----------
    coefficients : ndarray, shape (11,)
        DLT parameters of the (refined) camera's linear part (``camera.to_dlt()``).
    camera : Camera
        The calibrated camera (with distortion when it was estimated).
    rms_px : float
        ``sqrt(mean_i |r_i|^2)``: root mean square of the per-point residual distances (px).
    residuals : ndarray, shape (N, 2)
        Observed minus modelled image coordinates per control point (px).
    linear_coefficients : ndarray, shape (11,)
        The normalised linear solution before adjustment.
    linear_rms_px : float
        Its residual figure, defined as ``rms_px``.
    iterations : int
        Function evaluations of the non-linear adjustment (0 when ``refine=False``).
    """

    coefficients: FloatArray
    camera: Camera
    rms_px: float
    residuals: FloatArray
    linear_coefficients: FloatArray
    linear_rms_px: float
    iterations: int

    @property
    def residual_px(self) -> FloatArray:
        """Residual distance per control point, shape (N,), px."""
        return np.asarray(np.hypot(self.residuals[:, 0], self.residuals[:, 1]))


def _normalisation(points: FloatArray) -> FloatArray:
    """Hartley's similarity: centroid to 0, mean distance sqrt(dim); shape (dim+1, dim+1)."""
    dim = points.shape[1]
    centroid = points.mean(axis=0)
    mean_dist = float(np.mean(np.linalg.norm(points - centroid, axis=1)))
    s = np.sqrt(dim) / mean_dist
    T = np.eye(dim + 1)
    T[:dim, :dim] *= s
    T[:dim, dim] = -s * centroid
    return T


def _check_inputs(object_points: Any, image_points: Any) -> tuple[FloatArray, FloatArray]:
    X = np.asarray(object_points, dtype=np.float64)
    uv = np.asarray(image_points, dtype=np.float64)
    if X.ndim != 2 or X.shape[1] != 3:
        raise CalibrationError(f"object_points must have shape (N, 3), got {X.shape}")
    if uv.ndim != 2 or uv.shape[1] != 2:
        raise CalibrationError(f"image_points must have shape (N, 2), got {uv.shape}")
    if X.shape[0] != uv.shape[0]:
        raise CalibrationError(
            f"object_points ({X.shape[0]}) and image_points ({uv.shape[0]}) differ in length"
        )
    bad = np.flatnonzero(~(np.all(np.isfinite(X), axis=1) & np.all(np.isfinite(uv), axis=1)))
    if bad.size:
        raise CalibrationError(
            f"NaN or infinite coordinates at control points {bad.tolist()}: drop them first"
        )
    if X.shape[0] < 6:
        raise CalibrationError(f"the 3-D DLT needs at least 6 control points, got {X.shape[0]}")
    s = np.linalg.svd(X - X.mean(axis=0), compute_uv=False)
    if not s[0] > 0.0:
        raise CalibrationError("all control points coincide")
    if s[1] < 1e-9 * s[0]:
        raise CalibrationError("the control points are collinear")
    if s[2] < 1e-3 * s[0]:
        raise CalibrationError(
            "the control points are coplanar (thickness ratio "
            f"{s[2] / s[0]:.2g} < 1e-3): the 3-D DLT needs a volume of control"
        )
    s = np.linalg.svd(uv - uv.mean(axis=0), compute_uv=False)
    if not s[0] > 0.0 or s[1] < 1e-9 * s[0]:
        raise CalibrationError("the image points are collinear or coincide")
    return X, uv


def _linear_dlt(X: FloatArray, uv: FloatArray) -> FloatArray:
    """Homogeneous least-squares DLT with Hartley normalisation; returns P (3, 4), P[2,3]=1."""
    T = _normalisation(uv)
    U = _normalisation(X)
    Xn = X @ U[:3, :3].T + U[:3, 3]
    un = uv @ T[:2, :2].T + T[:2, 2]
    n = X.shape[0]
    Xh = np.column_stack([Xn, np.ones(n)])
    A = np.zeros((2 * n, 12))
    A[0::2, 0:4] = Xh
    A[0::2, 8:12] = -un[:, :1] * Xh
    A[1::2, 4:8] = Xh
    A[1::2, 8:12] = -un[:, 1:] * Xh
    _, s, vt = np.linalg.svd(A)
    if s[-2] <= 1e-9 * s[0]:
        raise CalibrationError(
            "degenerate control configuration: the DLT equations do not determine a "
            "unique camera (points and camera centre on a critical surface?)"
        )
    P = np.linalg.solve(T, vt[-1].reshape(3, 4)) @ U
    if abs(P[2, 3]) <= 1e-9 * float(np.max(np.abs(P[2, :3]))) * float(np.max(np.abs(X))):
        raise CalibrationError(
            "the world origin lies in the camera's principal plane: the DLT (L12 = 1) "
            "is undefined; put the origin inside the control volume"
        )
    return P / P[2, 3]


def _model(params: FloatArray, R0: FloatArray, X: FloatArray, terms: Sequence[int]) -> FloatArray:
    fx, fy, skew, cx, cy = params[:5]
    R = Rotation.from_rotvec(params[5:8]).as_matrix() @ R0
    xc = X @ R.T + params[8:11]
    xy = xc[:, :2] / xc[:, 2:3]
    if terms:
        dist = np.zeros(5)
        dist[list(terms)] = params[11:]
        xy = distort_normalized(xy, dist)
    return np.column_stack([fx * xy[:, 0] + skew * xy[:, 1] + cx, fy * xy[:, 1] + cy])


def _rms(residuals: FloatArray) -> float:
    return float(np.sqrt(np.mean(np.sum(residuals**2, axis=1))))


def _distortion_terms(distortion: bool | Sequence[str]) -> list[int]:
    if distortion is True:
        return list(range(5))
    if distortion is False:
        return []
    names = list(distortion)
    unknown = sorted(set(names) - set(DISTORTION_TERMS))
    if unknown:
        raise CalibrationError(
            f"unknown distortion terms {unknown}: choose from {DISTORTION_TERMS}"
        )
    return sorted(DISTORTION_TERMS.index(name) for name in set(names))


def dlt_calibrate(
    object_points: Any,
    image_points: Any,
    *,
    distortion: bool | Sequence[str] = False,
    refine: bool = True,
    image_size: tuple[int, int] | None = None,
    name: str = "",
) -> DltResult:
    """Calibrate one camera from control points with known world coordinates.

    Parameters
    ----------
    object_points : array_like, shape (N, 3)
        World coordinates of the control points (mm), N >= 6, not coplanar.
    image_points : array_like, shape (N, 2)
        Their observed image coordinates (px; u to the right, v downwards).
    distortion : bool or sequence of str
        Estimate Brown distortion terms too: ``True`` for all of ``k1, k2, p1, p2, k3``,
        or a selection such as ``("k1", "k2")``. Needs ``refine``.
    refine : bool
        Adjust the camera parameters by non-linear least squares on the image
        residuals after the linear solve (recommended: the linear solution is biased
        with noisy image data).
    image_size : (int, int), optional
        ``(width, height)`` for the returned camera; by default the smallest size
        holding all image points (at least 1 x 1).
    name : str
        Label of the returned camera.

    Returns
    -------
    DltResult
        ``coefficients`` (11,), ``camera``, ``rms_px``, ``residuals`` (N, 2) and the
        linear solution for comparison.

    Raises
    ------
    CalibrationError
        Fewer than 6 points (or fewer than half the number of parameters), NaN
        coordinates, coincident, collinear or coplanar control points, collinear
        image points, a degenerate linear system, the world origin in the camera's
        principal plane, control points behind the camera (left-handed image axes,
        e.g. v measured upwards), or an adjustment that does not converge.

    Notes
    -----
    Linear step (Woltring & Huiskes 1990, Eq. 13, homogeneous form): with Hartley's
    normalisations ``T`` (image) and ``U`` (world), the unit vector ``p`` minimising
    ``|A p|`` gives ``P = T^-1 P_n U``; ``L = P / P[2, 3]``. The camera follows from
    ``L`` by RQ decomposition (Eq. 15, :meth:`Camera.from_dlt`). Adjustment: the 11
    camera parameters ``fx, fy, s, cx, cy``, a rotation vector ``w`` (``R = exp(w) R0``)
    and ``t``, plus the chosen distortion terms, minimise ``sum |uv_i - project(X_i)|^2``
    (``scipy.optimize.least_squares``; Levenberg-Marquardt when there are at least as
    many residuals as parameters). Without distortion the refined camera is again an
    exact 11-parameter DLT. References: Abdel-Aziz & Karara (1971); Marzan & Karara
    (1975); Hartley, "In defense of the eight-point algorithm", IEEE PAMI 19(6), 1997.

    Examples
    --------
    >>> import numpy as np
    >>> from spotlab.calibration import dlt_calibrate
    >>> from spotlab.geometry import Camera
    >>> K = [[1200.0, 0.0, 640.0], [0.0, 1200.0, 480.0], [0.0, 0.0, 1.0]]
    >>> truth = Camera(K, None, np.eye(3), [0.0, 0.0, 3000.0], (1280, 960))
    >>> corners = [[x, y, z] for x in (0, 500) for y in (0, 400) for z in (0, 300)]
    >>> X = np.array(corners, dtype=float) - [250.0, 200.0, 150.0]
    >>> result = dlt_calibrate(X, truth.project(X), image_size=(1280, 960))
    >>> bool(result.rms_px < 1e-9), result.coefficients.shape
    (True, (11,))
    >>> bool(np.allclose(result.camera.K, K))
    True
    """
    X, uv = _check_inputs(object_points, image_points)
    terms = _distortion_terms(distortion)
    if terms and not refine:
        raise CalibrationError("distortion terms are estimated only with refine=True")
    n_params = 11 + len(terms)
    if 2 * X.shape[0] < n_params:
        raise CalibrationError(
            f"{n_params} parameters need at least {(n_params + 1) // 2} control points, "
            f"got {X.shape[0]}"
        )
    if image_size is None:
        image_size = (
            max(1, int(np.ceil(uv[:, 0].max())) + 1),
            max(1, int(np.ceil(uv[:, 1].max())) + 1),
        )
    P = _linear_dlt(X, uv)
    linear_L = P.ravel()[:11].copy()
    camera = Camera.from_dlt(linear_L, image_size, name)
    if np.any(X @ camera.R[2] + camera.t[2] <= 0.0):
        raise CalibrationError(
            "the control points lie behind the calibrated camera: the image axes and the "
            "world axes have opposite handedness (v measured upwards, or a left-handed "
            "world frame); flip v to v' = height - v or mirror one world axis "
            "(coefficients of such data: Camera.from_dlt(..., v_up=True))"
        )
    linear_resid = uv - camera.project(X)
    residuals, iterations = linear_resid, 0
    if refine:
        K = camera.K
        x0 = np.concatenate(
            [
                [K[0, 0], K[1, 1], K[0, 1], K[0, 2], K[1, 2]],
                np.zeros(3),
                camera.t,
                np.zeros(len(terms)),
            ]
        )
        R0 = camera.R

        def fun(p: FloatArray) -> FloatArray:
            return (_model(p, R0, X, terms) - uv).ravel()

        method = "lm" if 2 * X.shape[0] >= n_params else "trf"
        sol = least_squares(fun, x0, method=method, x_scale="jac", xtol=1e-12, ftol=1e-12)
        if sol.status <= 0 or not np.all(np.isfinite(sol.x)):
            raise CalibrationError(f"the non-linear DLT adjustment did not converge: {sol.message}")
        p = sol.x
        dist = np.zeros(5)
        dist[terms] = p[11:]
        Kr = [[p[0], p[2], p[3]], [0.0, p[1], p[4]], [0.0, 0.0, 1.0]]
        R = Rotation.from_rotvec(p[5:8]).as_matrix() @ R0
        camera = Camera(Kr, dist, R, p[8:11], image_size, name)
        residuals, iterations = uv - camera.project(X), int(sol.nfev)
        if not np.all(np.isfinite(residuals)):
            raise CalibrationError("the adjusted camera has control points behind it")
    return DltResult(
        coefficients=camera.to_dlt(),
        camera=camera,
        rms_px=_rms(residuals),
        residuals=residuals,
        linear_coefficients=linear_L,
        linear_rms_px=_rms(linear_resid),
        iterations=iterations,
    )


def dlt_reconstruct_on_plane(
    camera: Camera | Any,
    image_points: Any,
    plane_point: Any,
    plane_normal: Any,
) -> FloatArray:
    """World points on a known plane from one camera's image points.

    Parameters
    ----------
    camera : Camera or array_like, shape (11,)
        The calibrated camera, or 11 DLT parameters.
    image_points : array_like, shape (..., 2)
        Observed image coordinates (px); distortion is removed with the camera's model.
    plane_point : array_like, shape (3,)
        A point of the plane (mm).
    plane_normal : array_like, shape (3,)
        A normal vector of the plane (any length but zero).

    Returns
    -------
    ndarray, shape (..., 3)
        Intersections of the viewing rays with the plane (mm); NaN for NaN input, rays
        parallel to the plane, or intersections behind the camera.

    Raises
    ------
    CalibrationError
        For a zero or non-finite plane normal or point, or an invalid camera.

    Notes
    -----
    Ray ``X = X_c + lambda d`` with ``d = R' (x, y, 1)`` from the ideal normalised
    coordinates; the plane constraint ``N' (X - X_o) = 0`` (Woltring & Huiskes 1990,
    Eq. 2) gives ``lambda = N' (X_o - X_c) / N' d`` (Eq. 3).
    """
    if not isinstance(camera, Camera):
        camera = Camera.from_dlt(camera, (1, 1))
    X0 = np.asarray(plane_point, dtype=np.float64)
    N = np.asarray(plane_normal, dtype=np.float64)
    if X0.shape != (3,) or N.shape != (3,) or not np.all(np.isfinite(np.r_[X0, N])):
        raise CalibrationError("plane_point and plane_normal must be finite 3-vectors")
    if not np.linalg.norm(N) > 0.0:
        raise CalibrationError("plane_normal is the zero vector")
    xy = camera.normalize(image_points)
    d = np.concatenate([xy, np.ones((*xy.shape[:-1], 1))], axis=-1) @ camera.R
    C = camera.center
    denom = d @ N
    with np.errstate(divide="ignore", invalid="ignore"):
        lam = float(N @ (X0 - C)) / denom
    scale = np.linalg.norm(d, axis=-1) * np.linalg.norm(N)
    lam = np.where((np.abs(denom) > 1e-12 * scale) & (lam > 0.0), lam, np.nan)
    return np.asarray(C + lam[..., None] * d)
