"""Cold start of a wand calibration: cameras and wand poses from the data alone.

1. Principal distance of each camera from its view of the static reference object, with
   the principal point at the image centre, square pixels and no distortion: for a
   planar object (L-frame) the two orthogonality constraints of its plane's homography
   on the image of the absolute conic (Zhang 2000; with a triad of orthogonal arms they
   are Pribanić et al.'s constraints from the arms' vanishing points), for a
   three-dimensional object the linear DLT (Woltring & Huiskes Eq. 13-15).
2. Relative orientation of camera pairs from the essential matrix of the wand-end
   correspondences, along a maximum spanning tree of the pairs' common observations;
   each pair's baseline scaled so that the median triangulated wand length is the known
   length.
3. The world frame: the reference object's markers, triangulated with the initial rig,
   aligned to their known coordinates (Horn's absolute orientation).
4. Wand poses (centre and direction) by intersecting the rays of both ends.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from spotlab.calibration._rays import nearest_points
from spotlab.calibration._two_view import midpoints, relative_pose, rotation_residual
from spotlab.calibration.planar import fit_homography
from spotlab.core.errors import CalibrationError

__all__ = ["ColdStart", "cold_start", "focal_from_reference"]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

#: Median angle (rad) under which a camera pair is taken to have no baseline.
_NO_BASELINE_RAD = 1e-3


@dataclass
class ColdStart:
    """Initial estimate for the bundle adjustment."""

    focal: FloatArray  # (C,) px
    principal_point: FloatArray  # (C, 2) px
    rotations: FloatArray  # (C, 3, 3)
    translations: FloatArray  # (C, 3) mm
    centres: FloatArray  # (F, 3) wand centres, mm
    directions: FloatArray  # (F, 3) unit
    usable: BoolArray  # (F,) frames with both ends seen by >= 2 cameras
    tree: list[tuple[int, int]]  # (parent, child) camera pairs used
    root: int  # the camera the tree starts from


def _plane_frame(points: FloatArray) -> tuple[FloatArray, FloatArray, float] | None:
    """Origin, axes (3, 3; rows = in-plane u, v, normal) and relative thickness."""
    mean = points.mean(axis=0)
    _, s, vt = np.linalg.svd(points - mean)
    if s[1] <= 1e-9 * s[0]:
        return None
    return mean, vt, float(s[2] / s[0]) if len(s) > 2 else 0.0


def focal_from_reference(uv: FloatArray, points: FloatArray, size: tuple[int, int]) -> float | None:
    """Principal distance (px) of a camera from one view of a known object, or None.

    Parameters
    ----------
    uv : ndarray, shape (P, 2)
        Image points (px), NaN where unseen.
    points : ndarray, shape (P, 3)
        Known coordinates (mm).
    size : (width, height)
        Image size; the principal point is taken at its centre.

    Returns
    -------
    float or None
        None when the view does not determine it (fewer than 4 points, a view
        perpendicular to a planar object, an inconsistent solution).
    """
    seen = np.all(np.isfinite(uv), axis=1)
    uv, points = uv[seen], points[seen]
    if len(uv) < 4:
        return None
    frame = _plane_frame(points)
    if frame is None:
        return None
    mean, axes, thickness = frame
    centre = np.array([size[0] / 2.0, size[1] / 2.0])
    x = uv - centre
    if thickness < 1e-3:
        plane = (points - mean) @ axes[:2].T
        try:
            H = fit_homography(plane, x)
        except CalibrationError:
            return None
        h1, h2 = H[:, 0], H[:, 1]
        # h_i' diag(1, 1, f^2)^-1... in centred pixels: w = 1/f^2 weights the first two rows.
        a1 = h1[0] * h2[0] + h1[1] * h2[1]
        b1 = h1[2] * h2[2]
        a2 = h1[0] ** 2 + h1[1] ** 2 - h2[0] ** 2 - h2[1] ** 2
        b2 = h1[2] ** 2 - h2[2] ** 2
        # a w + b = 0 for w = 1/f^2, least squares over both constraints.
        den = a1 * a1 + a2 * a2
        w = -(a1 * b1 + a2 * b2) / den if den > 0 else -1.0
    else:
        if len(uv) < 6:
            return None
        from spotlab.calibration.dlt import _linear_dlt

        P = _linear_dlt(points, x)
        M = P[:, :3]
        # For P = K [R | t] with K = diag(f, f, 1): rows m1, m2 have norm f |m3|.
        m3 = np.linalg.norm(M[2])
        f2 = 0.5 * (np.sum(M[0] ** 2) + np.sum(M[1] ** 2)) / m3**2
        w = 1.0 / f2 if f2 > 0 else -1.0
    if not w > 0.0:
        return None
    f = float(1.0 / np.sqrt(w))
    if not 0.1 * max(size) < f < 20.0 * max(size):
        return None
    return f


def _spanning_tree(weights: NDArray[np.int_]) -> tuple[int, list[tuple[int, int]]]:
    """Root and edges (parent, child) of a maximum spanning tree (Prim)."""
    C = weights.shape[0]
    root = int(np.argmax(weights.sum(axis=1)))
    inside = {root}
    edges: list[tuple[int, int]] = []
    while len(inside) < C:
        best = (0, -1, -1)
        for p in inside:
            for q in range(C):
                if q not in inside and weights[p, q] > best[0]:
                    best = (int(weights[p, q]), p, q)
        if best[1] < 0:
            missing = sorted(set(range(C)) - inside)
            raise CalibrationError(
                f"camera(s) {', '.join(str(c + 1) for c in missing)} share no wand frame "
                "(both ends seen) with the others: the rig cannot be connected"
            )
        edges.append((best[1], best[2]))
        inside.add(best[2])
    return root, edges


def _horn(model: FloatArray, observed: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Rotation and translation with observed ~ R model + t (least squares, no scale)."""
    mm, mo = model.mean(axis=0), observed.mean(axis=0)
    u, _, vt = np.linalg.svd((observed - mo).T @ (model - mm))
    R = u @ np.diag([1.0, 1.0, float(np.linalg.det(u @ vt))]) @ vt
    return R, mo - R @ mm


def cold_start(
    wand_uv: FloatArray,
    wand_length: float,
    frame_uv: FloatArray,
    frame_points: FloatArray,
    sizes: list[tuple[int, int]],
) -> ColdStart:
    """Initial cameras and wand poses from wand and reference-object observations.

    Parameters
    ----------
    wand_uv : ndarray, shape (F, C, 2, 2)
    wand_length : float
    frame_uv : ndarray, shape (C, P, 2)
    frame_points : ndarray, shape (P, 3)
    sizes : list of (width, height)

    Raises
    ------
    CalibrationError
        When the rig cannot be connected, two cameras share one position, or the
        reference object is not seen well enough to fix the world frame.
    """
    F, C = wand_uv.shape[:2]
    pp = np.array([[w / 2.0, h / 2.0] for w, h in sizes])
    focal = np.array(
        [focal_from_reference(frame_uv[c], frame_points, sizes[c]) or np.nan for c in range(C)]
    )
    if not np.any(np.isfinite(focal)):
        # No view of the reference object determines it: a normal lens (about 53 degrees
        # across the width) is the starting point; the adjustment moves it.
        focal = np.array([float(w) for w, _ in sizes])
    else:
        ratio = np.nanmedian(focal / np.array([w for w, _ in sizes]))
        focal = np.where(np.isfinite(focal), focal, ratio * np.array([w for w, _ in sizes]))

    xn = (wand_uv - pp[None, :, None, :]) / focal[None, :, None, None]  # (F, C, 2, 2)
    both = np.all(np.isfinite(wand_uv), axis=(2, 3))  # (F, C)
    weights = np.einsum("fc,fd->cd", both.astype(np.int64), both.astype(np.int64))
    np.fill_diagonal(weights, 0)
    weights[weights < 8] = 0
    root, tree = _spanning_tree(weights)

    rotations = np.zeros((C, 3, 3))
    translations = np.zeros((C, 3))
    rotations[root] = np.eye(3)
    for p, q in tree:
        common = both[:, p] & both[:, q]
        x1 = xn[common, p].reshape(-1, 2)
        x2 = xn[common, q].reshape(-1, 2)
        if rotation_residual(x1, x2) < _NO_BASELINE_RAD:
            raise CalibrationError(
                f"cameras {p + 1} and {q + 1} see the wand along rays related by a pure "
                "rotation: they share one position (no baseline), so depth is undetermined"
            )
        R, t = relative_pose(x1, x2)
        # Scale: wand length from the pair, in the frame of camera p.
        h1 = np.concatenate([x1, np.ones((len(x1), 1))], axis=1)
        h2 = np.concatenate([x2, np.ones((len(x2), 1))], axis=1)
        X, _ = midpoints(np.zeros(3), h1, -R.T @ t, h2 @ R)
        ends = X.reshape(-1, 2, 3)
        lengths = np.linalg.norm(ends[:, 1] - ends[:, 0], axis=1)
        scale = wand_length / float(np.nanmedian(lengths))
        rotations[q] = R @ rotations[p]
        translations[q] = R @ translations[p] + scale * t

    centres_c = -np.einsum("cji,cj->ci", rotations, translations)

    def rays(xy: FloatArray) -> FloatArray:
        """World ray directions (C, N, 3) of normalised points (C, N, 2)."""
        h = np.concatenate([xy, np.ones((*xy.shape[:-1], 1))], axis=-1)
        d = np.einsum("cni,cij->cnj", h, rotations)
        return d / np.linalg.norm(d, axis=-1, keepdims=True)

    # World frame from the reference object (without one, the root camera's frame).
    if frame_points.shape[0]:
        fxn = (frame_uv - pp[:, None, :]) / focal[:, None, None]
        fseen = np.all(np.isfinite(frame_uv), axis=-1)
        Y, _ = nearest_points(centres_c, rays(np.nan_to_num(fxn)), fseen)
        ok = np.all(np.isfinite(Y), axis=1)
        _check_reference_span(frame_points[ok], int(np.count_nonzero(ok)))
        R_a, t_a = _horn(frame_points[ok], Y[ok])
        translations = np.einsum("cij,j->ci", rotations, t_a) + translations
        rotations = rotations @ R_a
        centres_c = -np.einsum("cji,cj->ci", rotations, translations)

    # Wand poses.
    ends_seen = np.all(np.isfinite(wand_uv), axis=-1)  # (F, C, 2)
    flat = np.nan_to_num(xn.transpose(1, 0, 2, 3).reshape(C, F * 2, 2))
    X, _ = nearest_points(centres_c, rays(flat), ends_seen.transpose(1, 0, 2).reshape(C, F * 2))
    ends = X.reshape(F, 2, 3)
    usable = np.all(np.isfinite(ends), axis=(1, 2))
    centres = 0.5 * (ends[:, 0] + ends[:, 1])
    direction = ends[:, 1] - ends[:, 0]
    norm = np.linalg.norm(direction, axis=1, keepdims=True)
    usable &= norm[:, 0] > 0
    with np.errstate(invalid="ignore", divide="ignore"):
        direction = direction / norm
    return ColdStart(
        focal=focal,
        principal_point=pp,
        rotations=rotations,
        translations=translations,
        centres=centres,
        directions=direction,
        usable=usable,
        tree=[(p, q) for p, q in tree],
        root=root,
    )


def _check_reference_span(points: FloatArray, n: int) -> None:
    if n < 3:
        raise CalibrationError(
            f"only {n} marker(s) of the reference object are seen by two or more cameras: "
            "the world frame needs at least 3 non-collinear ones"
        )
    s = np.linalg.svd(points - points.mean(axis=0), compute_uv=False)
    if s[1] <= 1e-6 * s[0]:
        raise CalibrationError(
            "the reference object's markers seen by two or more cameras are collinear: "
            "they do not fix the world axes"
        )
