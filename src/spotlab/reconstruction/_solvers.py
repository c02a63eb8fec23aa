"""The triangulation estimators, vectorised over points: ODLE, DLT, midpoint, Gauss-Newton.

Every function works in a world frame centred on the rig (``X' = X - origin``), takes
per camera the viewing data of all N points (NaN or zero weight where a camera does not
see a point) and returns centred points, shape (N, 3), with the conditioning of each
point's normal equations.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from spotlab.geometry import Camera
from spotlab.reconstruction._normal_equations import Normal3
from spotlab.reconstruction._rays import Lens, brown

FloatArray = NDArray[np.float64]


class Frame:
    """What the estimators need of a rig, computed once per call.

    Parameters
    ----------
    cameras : tuple of Camera
    origin : ndarray, shape (3,)
        World point (mm) the computations are centred on.

    Attributes
    ----------
    t : ndarray, shape (C, 3)
        Camera translations in the centred frame (``t + R origin``).
    lenses : list of Lens
        The intrinsic parameters for undistortion.
    odle_matrix : ndarray, shape (9, 7 C)
        Maps the per-ray sums of :func:`odle` to its normal equations.
    r3 : ndarray, shape (C, 3)
        Optical axes (third rows of R).
    f2 : ndarray, shape (C, 1)
        Squared principal distances (px^2).
    """

    def __init__(self, cameras: tuple[Camera, ...], origin: FloatArray) -> None:
        self.cameras = cameras
        self.origin = origin
        self.t = np.stack([cam.t + cam.R @ origin for cam in cameras])
        self.lenses = [Lens(cam) for cam in cameras]
        self.odle_matrix = _odle_matrix(np.stack([cam.R for cam in cameras]), self.t)
        self.r3 = np.stack([cam.R[2] for cam in cameras])
        self.f2 = np.array([[cam.K[0, 0] * cam.K[1, 1]] for cam in cameras])


@dataclass
class Views:
    """The observations of N points by C cameras, undistorted once.

    Attributes
    ----------
    frame : Frame
    cameras : tuple of Camera
    t : ndarray, shape (C, 3)
        Camera translations in the centred frame (``t + R origin``).
    x, y : ndarray, shape (C, N)
        Ideal normalised coordinates, 0 where unseen.
    seen : ndarray of bool, shape (C, N)
    user_weights : ndarray, shape (C, N), or None
        The caller's weights (None: 1).
    weights : ndarray, shape (C, N)
        User weights, 0 where unseen (computed on first use).
    """

    frame: Frame
    cameras: tuple[Camera, ...]
    t: FloatArray
    x: FloatArray
    y: FloatArray
    seen: NDArray[np.bool_]
    user_weights: FloatArray | None

    @classmethod
    def build(
        cls,
        frame: Frame,
        x: FloatArray,
        y: FloatArray,
        seen: NDArray[np.bool_],
        w: FloatArray | None,
    ) -> Views:
        """Views of undistorted observations ``x, y`` (C, N) (see
        :func:`spotlab.reconstruction._rays.normalize_seen`); ``w`` (C, N) are the user
        weights (None: 1)."""
        return cls(frame, frame.cameras, frame.t, x, y, seen, w)

    @functools.cached_property
    def weights(self) -> FloatArray:
        """User weights, 0 where unseen, shape (C, N)."""
        if self.user_weights is None:
            return self.seen.astype(np.float64)
        return np.where(self.seen, self.user_weights, 0.0)

    def depth(self, c: int, X: FloatArray) -> FloatArray:
        """Depth ``z_cam`` (mm) of centred points X (N, 3) in camera c."""
        r = self.cameras[c].R[2]
        return np.asarray(X @ r + self.t[c, 2])


#: Index pairs of the 6 distinct entries of a symmetric 3x3 matrix, in Normal3's order.
_PAIRS = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))


def _odle_matrix(R: FloatArray, t: FloatArray) -> FloatArray:
    """The linear map from the per-ray sums of :func:`odle` to its normal equations.

    With ``m = (x, y, 1)`` and ``d = R' m`` the ray direction of camera c, ``S = m m'``
    has the 6 distinct entries ``(x^2, xy, x, y^2, y, 1)``; ``A = sum w I - sum
    (w / m'm) R' S R`` and ``b = sum w c + sum (w / m'm) R' S t`` (``R c = -t``) are
    linear in them. Columns ``7 c .. 7 c + 5`` take ``(w / m'm) S`` of camera c, column
    ``7 c + 6`` its ``w``; rows are the 6 entries of A then the 3 of b.
    """
    C = R.shape[0]
    M = np.zeros((9, 7 * C))
    for c in range(C):
        Rc, tc = R[c], t[c]
        for q, (i, j) in enumerate(_PAIRS):
            for p, (r, s) in enumerate(_PAIRS):
                coef = Rc[i, r] * Rc[j, s]
                if i != j:
                    coef += Rc[j, r] * Rc[i, s]
                M[p, 7 * c + q] = -coef
            for r in range(3):
                coef = Rc[i, r] * tc[j]
                if i != j:
                    coef += Rc[j, r] * tc[i]
                M[6 + r, 7 * c + q] = coef
        for p, (r, s) in enumerate(_PAIRS):
            M[p, 7 * c + 6] = float(r == s)
        M[6:, 7 * c + 6] = -Rc.T @ tc  # the perspective centre
    return M


def odle(views: Views, iterations: int, depth_weighted: bool) -> tuple[FloatArray, FloatArray]:
    """Woltring & Huiskes (1990) Eq. 6: the point nearest to all rays, weighted.

    ``A = sum_j w_j (I - n_j n_j')``, ``b = sum_j w_j (I - n_j n_j') c_j``, ``X = A^-1 b``
    with unit ray directions ``n_j`` and perspective centres ``c_j``. With
    ``depth_weighted`` every pass after the first multiplies the user weights by
    ``(f_j / z_j)^2`` from the previous estimate, so that each squared ray distance is
    measured in pixels at the point's depth: the estimate then minimises (to first
    order) the image error, the maximum-likelihood criterion for pixel noise.

    The sums over rays are one matrix product (see :func:`_odle_matrix`) of 7 numbers
    per ray: ``(w / m'm) (x^2, xy, x, y^2, y, 1)`` and ``w``.
    """
    C, N = views.seen.shape
    x, y = views.x, views.y
    Q = np.empty((C, 7, N))
    w = Q[:, 6]
    np.copyto(w, views.seen if views.user_weights is None else views.weights)
    wn = Q[:, 5]
    np.multiply(x, x, out=wn)
    wn += y * y
    wn += 1.0
    np.divide(w, wn, out=wn)
    np.multiply(wn, x, out=Q[:, 2])
    np.multiply(Q[:, 2], x, out=Q[:, 0])
    np.multiply(Q[:, 2], y, out=Q[:, 1])
    np.multiply(wn, y, out=Q[:, 4])
    np.multiply(Q[:, 4], y, out=Q[:, 3])
    frame = views.frame
    M = frame.odle_matrix
    passes = iterations if depth_weighted else 0
    if passes:
        X = _normal(_product(M, Q.reshape(7 * C, N))).points()
    else:
        X, conditioning = _normal(_product(M, Q.reshape(7 * C, N))).solve()
    for k in range(passes):
        z = frame.r3 @ X.T
        z += views.t[:, 2:3]
        z *= z
        np.divide(frame.f2, z, out=z)
        scaled = Q if k == passes - 1 else np.empty_like(Q)
        np.multiply(Q, z[:, None, :], out=scaled)
        normal = _normal(_product(M, scaled.reshape(7 * C, N)))
        if k < passes - 1:
            X = normal.points()
        else:
            X, conditioning = normal.solve()
    return X, conditioning


#: Columns per matrix product: OpenBLAS runs products of fewer than 2^18 multiply-adds on
#: the calling thread; larger ones start its threads, which on a busy machine (or beside
#: the caller's own workers) made the product up to 10 times slower.
_PRODUCT_FLOPS = 1 << 18


def _product(M: FloatArray, Q: FloatArray) -> FloatArray:
    """``M @ Q`` in column slices small enough to run on the calling thread."""
    out = np.empty((M.shape[0], Q.shape[1]))
    width = max(1, _PRODUCT_FLOPS // (M.shape[0] * M.shape[1]))
    for j in range(0, Q.shape[1], width):
        np.matmul(M, Q[:, j : j + width], out=out[:, j : j + width])
    return out


def _normal(entries: FloatArray) -> Normal3:
    """Normal equations given as 9 rows (6 of A, 3 of b), shape (9, N)."""
    normal = Normal3(0)
    normal.a = entries[:6]
    normal.b = entries[6:]
    return normal


def _add_rows(
    normal: Normal3,
    g1: FloatArray,
    g2: FloatArray,
    e1: FloatArray,
    e2: FloatArray,
) -> None:
    """Add the row pair ``g1' X = e1``, ``g2' X = e2`` (g of shape (3, N)) to the normal
    equations."""
    a = normal.a
    for i, (r, s) in enumerate(((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))):
        a[i] += g1[r] * g1[s] + g2[r] * g2[s]
    for k in range(3):
        normal.b[k] += g1[k] * e1 + g2[k] * e2


def _pixel_rows(
    views: Views, c: int, scale: FloatArray | float
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """DLT rows of camera c in pixels, divided by ``scale`` (the projective depth).

    In normalised coordinates ``(x r3 - r1)' X = t1 - x t3`` and
    ``(y r3 - r2)' X = t2 - y t3`` (Woltring & Huiskes 1990, Eq. 4 multiplied by its
    denominator); mapped by the 2x2 pixel part of K their residuals are ``z`` times the
    (ideal) pixel residuals.
    """
    cam = views.cameras[c]
    R, t, K = cam.R, views.t[c], cam.K
    x, y = views.x[c], views.y[c]
    rx = np.outer(R[2], x) - R[0][:, None]
    ry = np.outer(R[2], y) - R[1][:, None]
    ex = t[0] - x * t[2]
    ey = t[1] - y * t[2]
    s = np.sqrt(views.weights[c]) / scale
    g1 = (K[0, 0] * rx + K[0, 1] * ry) * s
    e1 = (K[0, 0] * ex + K[0, 1] * ey) * s
    return g1, (K[1, 1] * s) * ry, e1, (K[1, 1] * s) * ey


def dlt(views: Views, iterations: int) -> tuple[FloatArray, FloatArray]:
    """Woltring & Huiskes (1990) Eq. 7-8 with iterative re-weighting.

    The first pass is the plain least-squares solution of the DLT equations (each
    camera's rows divided by its ``L12`` normalisation, the depth of the world origin
    ``t_z``, as DLTdv and the textbook DLT have them; by the depth of the rig centre if
    the world origin lies in a camera's principal plane). Each further pass divides the
    rows by the projective depth of the previous estimate, which makes every residual a
    pixel residual and removes the bias of the unweighted solution (Woltring & Huiskes
    1990, p. 204: "two or three iterations are usually sufficient").
    """
    N = views.seen.shape[1]
    X = np.zeros((N, 3))
    conditioning = np.zeros(N)
    for k in range(1 + iterations):
        normal = Normal3(N)
        for c, cam in enumerate(views.cameras):
            if k == 0:
                tz = float(cam.t[2])
                ok = abs(tz) > 1e-9 * float(np.linalg.norm(cam.t))
                scale: FloatArray | float = abs(tz) if ok else abs(float(views.t[c, 2]))
            else:
                scale = views.depth(c, X)
            _add_rows(normal, *_pixel_rows(views, c, scale))
        X, conditioning = normal.solve()
    return X, conditioning


def midpoint(views: Views) -> FloatArray:
    """Yeadon (1990) Fig. 4: midpoint of the common perpendicular of two rays per point.

    ``P = c1 + s d1`` and ``Q = c2 + u d2`` with ``(P - Q)`` normal to both rays:
    ``s = (b e - c d) / (a c - b^2)``, ``u = (a e - b d) / (a c - b^2)`` where
    ``a = d1'd1, b = d1'd2, c = d2'd2, d = d1'w, e = d2'w, w = c1 - c2``. Each point
    must be seen by exactly two cameras (checked by the caller).
    """
    N = views.seen.shape[1]
    order = np.argsort(~views.seen, axis=0, kind="stable")[:2]  # the two seeing cameras
    cols = np.arange(N)
    ends = []
    for slot in range(2):
        cam_index = order[slot]
        R = np.stack([cam.R for cam in views.cameras])[cam_index]  # (N, 3, 3)
        ray = np.stack([views.x[cam_index, cols], views.y[cam_index, cols], np.ones(N)], 1)
        d = np.einsum("nji,nj->ni", R, ray)
        centre = -np.einsum("nji,nj->ni", R, views.t[cam_index])
        ends.append((centre, d))
    (c1, d1), (c2, d2) = ends
    w = c1 - c2
    a = np.sum(d1 * d1, 1)
    b = np.sum(d1 * d2, 1)
    c = np.sum(d2 * d2, 1)
    d = np.sum(d1 * w, 1)
    e = np.sum(d2 * w, 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        den = a * c - b * b
        s = (b * e - c * d) / den
        u = (a * e - b * d) / den
    return np.asarray(0.5 * (c1 + s[:, None] * d1 + c2 + u[:, None] * d2))


def refine(
    views: Views, uv: FloatArray, X: FloatArray, iterations: int
) -> tuple[FloatArray, FloatArray]:
    """Gauss-Newton on the weighted reprojection error in distorted pixels.

    Per camera the Jacobian of the projection is ``-(M / z) [x r3 - r1; y r3 - r2]``
    with ``M`` the pixel part of K times the Brown Jacobian: the same rows as the DLT,
    so the same normal equations serve.
    """
    N = views.seen.shape[1]
    conditioning = np.zeros(N)
    for _ in range(iterations):
        normal = Normal3(N)
        for c, cam in enumerate(views.cameras):
            R, t, K = cam.R, views.t[c], cam.K
            xc = X @ R.T + t
            z = xc[:, 2]
            x, y = xc[:, 0] / z, xc[:, 1] / z
            xd, yd, j00, j01, j11 = brown(x, y, cam.dist)
            u = K[0, 0] * xd + K[0, 1] * yd + K[0, 2]
            v = K[1, 1] * yd + K[1, 2]
            s = np.sqrt(views.weights[c]) / z
            seen = views.seen[c]
            r1 = np.where(seen, uv[c, :, 0] - u, 0.0) * np.sqrt(views.weights[c])
            r2 = np.where(seen, uv[c, :, 1] - v, 0.0) * np.sqrt(views.weights[c])
            m00 = (K[0, 0] * j00 + K[0, 1] * j01) * s
            m01 = (K[0, 0] * j01 + K[0, 1] * j11) * s
            m10 = K[1, 1] * j01 * s
            m11 = K[1, 1] * j11 * s
            rx = R[0][:, None] - np.outer(R[2], x)
            ry = R[1][:, None] - np.outer(R[2], y)
            _add_rows(normal, m00 * rx + m01 * ry, m10 * rx + m11 * ry, r1, r2)
        step, conditioning = normal.solve()
        X = X + step
    return X, conditioning
