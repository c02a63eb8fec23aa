"""Selvik's two-plane calibration cage and its 180-degree rotation check.

The cage carries control markers on two parallel planes at known coordinates (Selvik
1974; Woltring & Huiskes 1990, "SMAC" section and Fig. 5). Each camera is calibrated by
the DLT from the markers of both planes. The cage frame is fixed to the lower plane
(``z = 0``), with ``z`` along the normal of the planes.

The position of the upper plane relative to the lower one is the weak point: "one
rotational and two positional degrees of freedom of these planes with respect to each
other may entail inaccuracies. By viewing the object in one position, and once again after
a rotation of approximately 180 degrees about the normal on the two planes, the
inaccuracies can be assessed and eliminated" (Woltring & Huiskes 1990). An in-plane shift
``delta`` of the upper plane is a shear of space, which the DLT absorbs without any residual;
after the half turn the same error shears the other way, so the cage reconstructed with
the calibration of one position deviates from its stated shape by about ``2 delta``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from spotlab.calibration.dlt import DltResult, dlt_calibrate
from spotlab.core.errors import CalibrationError
from spotlab.geometry import Camera, Rig

__all__ = ["CageCalibration", "RotationCheck", "cage_calibrate", "rotation_check"]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

#: Largest spread of a plane's z coordinates, as a fraction of the plane spacing.
PLANE_FLATNESS = 0.05
#: Accepted departure of the cage's turn from a half turn about its normal (degrees).
HALF_TURN_TOLERANCE_DEG = 30.0


@dataclass(frozen=True)
class CageCalibration:
    """Outcome of :func:`cage_calibrate`.

    Attributes
    ----------
    rig : Rig
        The calibrated cameras; world frame = cage frame (mm).
    results : tuple of DltResult
        The DLT result of each camera (coefficients, residuals, linear solution).
    rms_px : ndarray, shape (C,)
        Reprojection RMS per camera (px).
    upper : ndarray of bool, shape (P,)
        Which cage markers belong to the upper plane.
    used : ndarray of bool, shape (C, P)
        Which markers each camera was calibrated from (finite image points).
    """

    rig: Rig
    results: tuple[DltResult, ...]
    rms_px: FloatArray
    upper: BoolArray
    used: BoolArray


@dataclass(frozen=True)
class RotationCheck:
    """Outcome of :func:`rotation_check`.

    Attributes
    ----------
    discrepancy_mm : ndarray, shape (P, 3)
        Per marker, the cage as reconstructed after the half turn minus its stated
        coordinates, in the cage frame (mm), averaged over both directions (position 2
        reconstructed with the calibration of position 1, and the reverse), after a rigid
        fit on the lower (reference) plane. NaN for markers seen by fewer than 2 cameras.
    discrepancy_norm_mm : ndarray, shape (P,)
        Its length per marker (mm).
    rms_mm, max_mm : float
        RMS and largest ``discrepancy_norm_mm`` over the markers (mm).
    upper_plane_shift_mm : ndarray, shape (2,)
        Estimated in-plane error of the stated upper-plane coordinates: the true upper
        plane lies at the stated one plus this shift (half the mean in-plane discrepancy
        of the upper plane), mm.
    upper_plane_rotation_deg : float
        Estimated rotation of the true upper plane about the normal, relative to the stated
        one (degrees, counter-clockwise seen from +z): the rotation of the upper plane's
        discrepancy field about its centroid.
    corrected_cage_points : ndarray, shape (P, 3)
        The stated coordinates with the upper plane turned by that rotation about its
        centroid and then shifted by ``upper_plane_shift_mm``.
    turn_deg : float
        Measured turn of the cage between the two positions (degrees, ideally 180).
    axis_tilt_deg : float
        Angle between the turn axis and the normal of the planes (degrees).
    tolerance_mm : float
        The tolerance of the verdict.
    passed : bool
        ``max_mm <= tolerance_mm``.
    verdict : str
        One plain sentence.
    first, second : CageCalibration
        The calibrations from each position.
    """

    discrepancy_mm: FloatArray
    discrepancy_norm_mm: FloatArray
    rms_mm: float
    max_mm: float
    upper_plane_shift_mm: FloatArray
    upper_plane_rotation_deg: float
    corrected_cage_points: FloatArray
    turn_deg: float
    axis_tilt_deg: float
    tolerance_mm: float
    passed: bool
    verdict: str
    first: CageCalibration
    second: CageCalibration


def _split_planes(cage_points: Any) -> tuple[FloatArray, BoolArray]:
    """Validated cage points (P, 3) and the upper-plane mask; CalibrationError otherwise."""
    X = np.asarray(cage_points, dtype=np.float64)
    if X.ndim != 2 or X.shape[1] != 3:
        raise CalibrationError(f"cage_points must have shape (P, 3), got {X.shape}")
    if not np.all(np.isfinite(X)):
        raise CalibrationError("cage_points hold NaN or infinite coordinates")
    if X.shape[0] < 6:
        raise CalibrationError(f"a calibration cage needs at least 6 markers, got {X.shape[0]}")
    z = X[:, 2]
    spacing = float(np.ptp(z))
    extent = float(np.ptp(X[:, :2], axis=0).max())
    if not spacing > 1e-3 * extent:
        raise CalibrationError(
            "the cage markers are coplanar (one plane only): the DLT needs markers on two "
            "planes z = const some distance apart"
        )
    upper = z > z.min() + 0.5 * spacing
    for name, mask in (("lower", ~upper), ("upper", upper)):
        if np.ptp(z[mask]) > PLANE_FLATNESS * spacing:
            raise CalibrationError(
                f"the {name} plane's markers spread over {np.ptp(z[mask]):.3g} mm in z: "
                "cage markers must lie on two parallel planes z = const"
            )
        xy = X[mask, :2] - X[mask, :2].mean(axis=0)
        sv = np.linalg.svd(xy, compute_uv=False) if mask.sum() >= 2 else np.zeros(2)
        if mask.sum() < 3 or sv[1] < 1e-6 * max(extent, 1e-300):
            raise CalibrationError(
                f"the {name} plane needs at least 3 markers not on one line, got {int(mask.sum())}"
            )
    return X, upper


def _image_stack(image_points: Any, n_markers: int, what: str) -> FloatArray:
    uv = np.asarray(image_points, dtype=np.float64)
    if uv.ndim == 2:
        uv = uv[None]
    if uv.ndim != 3 or uv.shape[1:] != (n_markers, 2):
        raise CalibrationError(
            f"{what} must have shape (C, {n_markers}, 2) or ({n_markers}, 2), got {uv.shape}"
        )
    return uv


def cage_calibrate(
    cage_points: Any,
    image_points: Any,
    *,
    distortion: bool | Sequence[str] = False,
    image_size: tuple[int, int] | None = None,
    names: Sequence[str] | None = None,
) -> CageCalibration:
    """Calibrate cameras by the DLT from a two-plane calibration cage.

    Parameters
    ----------
    cage_points : array_like, shape (P, 3)
        Stated marker coordinates in the cage frame (mm): the lower plane at one ``z``, the
        upper plane at another, ``z`` along the normal of the planes.
    image_points : array_like, shape (C, P, 2) or (P, 2)
        Image coordinates per camera (px); NaN where a camera does not see a marker
        (each camera is calibrated from the markers it sees).
    distortion : bool or sequence of str
        Distortion terms to estimate, as in :func:`dlt_calibrate`.
    image_size : (width, height), optional
        Image size of every camera (px); by default from the image points.
    names : sequence of str, optional
        Camera names; ``cam1 ... camC`` by default.

    Returns
    -------
    CageCalibration
        The rig in the cage frame, the per-camera DLT results and residual figures.

    Raises
    ------
    CalibrationError
        Malformed or non-finite cage points; fewer than 6 markers; all markers in one
        plane (coplanar); markers not on two parallel planes; a plane with fewer than 3
        non-collinear markers; and, per camera (named), every error of
        :func:`dlt_calibrate` on the markers it sees (fewer than 6, coplanar, ...).
    """
    X, upper = _split_planes(cage_points)
    uv = _image_stack(image_points, X.shape[0], "image_points")
    n_cam = uv.shape[0]
    if names is None:
        names = [f"cam{k + 1}" for k in range(n_cam)]
    if len(names) != n_cam:
        raise CalibrationError(f"{len(names)} names for {n_cam} cameras")
    used = np.all(np.isfinite(uv), axis=-1)
    results = []
    for k in range(n_cam):
        try:
            results.append(
                dlt_calibrate(
                    X[used[k]],
                    uv[k, used[k]],
                    distortion=distortion,
                    image_size=image_size,
                    name=names[k],
                )
            )
        except CalibrationError as exc:
            raise CalibrationError(f"camera {names[k]!r}: {exc}") from None
    return CageCalibration(
        rig=Rig([r.camera for r in results]),
        results=tuple(results),
        rms_px=np.array([r.rms_px for r in results]),
        upper=upper,
        used=used,
    )


def _triangulate(cameras: Sequence[Camera], uv: FloatArray) -> FloatArray:
    """Linear least-squares intersection of the rays, (C, P, 2) -> (P, 3); NaN if < 2 views."""
    rows = []
    for camera, pts in zip(cameras, uv, strict=True):
        xy = camera.normalize(pts)  # (P, 2), distortion removed
        Rt = np.column_stack([camera.R, camera.t])
        for axis in (0, 1):
            rows.append(xy[:, axis : axis + 1] * Rt[2] - Rt[axis])  # (P, 4)
    A = np.stack(rows, axis=1)  # (P, 2C, 4)
    seen = np.all(np.isfinite(A), axis=-1)
    A = np.where(seen[..., None], A, 0.0)
    A /= np.maximum(np.linalg.norm(A, axis=-1, keepdims=True), 1e-300)
    h = np.linalg.svd(A)[2][:, -1, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        X = h[:, :3] / h[:, 3:]
    X[seen.sum(axis=1) < 4] = np.nan
    return np.asarray(X)


def _kabsch(model: FloatArray, observed: FloatArray) -> tuple[FloatArray, FloatArray]:
    """R, t with observed ~ R model + t (least squares, no reflection)."""
    mc, oc = model.mean(axis=0), observed.mean(axis=0)
    U, _, Vt = np.linalg.svd((observed - oc).T @ (model - mc))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    R = U @ D @ Vt
    return R, oc - R @ mc


def _cage_frame_discrepancy(
    X: FloatArray, upper: BoolArray, Z: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Reconstruction Z (P, 3) taken into the cage frame by the lower plane, minus X."""
    ok = np.all(np.isfinite(Z), axis=1)
    lower = ok & ~upper
    if lower.sum() < 3:
        raise CalibrationError(
            "fewer than 3 lower-plane markers were seen by two cameras in both positions: "
            "the cage cannot be compared"
        )
    R, t = _kabsch(X[lower], Z[lower])
    return (Z - t) @ R - X, R


def _upper_plane_error(xy: FloatArray, disc: FloatArray) -> tuple[FloatArray, float]:
    """In-plane shift (half the mean discrepancy) and rotation (rad) of the upper plane."""
    if xy.shape[0] == 0:
        return np.full(2, np.nan), float("nan")
    rel = xy - xy.mean(axis=0)
    d = disc - disc.mean(axis=0)
    phi = float(np.sum(rel[:, 0] * d[:, 1] - rel[:, 1] * d[:, 0]) / np.sum(rel**2))
    return 0.5 * disc.mean(axis=0), phi


def rotation_check(
    cage_points: Any,
    image_points_1: Any,
    image_points_2: Any,
    *,
    tolerance_mm: float,
    distortion: bool | Sequence[str] = False,
    image_size: tuple[int, int] | None = None,
) -> RotationCheck:
    """Selvik's 180-degree rotation check of a two-plane cage and its calibration.

    The cage is photographed by the same fixed cameras twice: in one position, and again
    after a turn of about 180 degrees about the normal of its planes (its vertical axis).

    Parameters
    ----------
    cage_points : array_like, shape (P, 3)
        Stated marker coordinates in the cage frame (mm), as for :func:`cage_calibrate`.
    image_points_1, image_points_2 : array_like, shape (C, P, 2)
        Image coordinates (px) of the markers in the first and second position, C >= 2
        cameras in the same order; NaN where not seen.
    tolerance_mm : float
        Largest acceptable discrepancy of a marker (mm) for the verdict. It must lie above
        what image noise alone gives (for 0.2 px noise, 2 cameras at 2.5 m and f = 1500 px,
        about 1 mm: see docs/calibration-objects.md).
    distortion : bool or sequence of str
        Distortion terms to estimate, as in :func:`dlt_calibrate`.
    image_size : (width, height), optional
        Image size of every camera (px).

    Returns
    -------
    RotationCheck
        Per-marker and overall discrepancies, the estimated error of the upper plane,
        the measured turn, and a verdict.

    Raises
    ------
    CalibrationError
        Every error of :func:`cage_calibrate`; fewer than 2 cameras; the two positions
        not related by a turn of 180 +- 30 degrees about an axis within 30 degrees of
        the normal of the planes (the check would see nothing); fewer than 3 lower-plane
        markers reconstructed; a non-positive tolerance.

    Notes
    -----
    Calibrating from the stated coordinates ``X`` absorbs any affine error of them, in
    particular a shift ``delta`` of the upper plane (a shear ``X -> X + (z / h) delta``):
    each camera then images the cage with zero residual, but in a sheared frame. The
    cage in position 2 is ``Y = R X_true + c`` with ``R`` the half turn, so
    ``R delta = -delta``; reconstructed with the calibration of position 1 and brought
    back to the cage frame by a rigid fit on the lower (reference) plane, the upper plane
    appears at ``X + 2 delta``. The check reconstructs each position with the other
    position's calibration (linear ray intersection, distortion removed), averages the
    two discrepancies, and estimates ``delta`` as half the upper plane's mean in-plane
    discrepancy. An error the DLT absorbs shows twice; one it cannot absorb, such as a
    rotation ``theta`` of the upper plane about the normal (not an affine map), already
    leaves reprojection residuals in each position and shows about once: on synthetic
    cages the upper plane's discrepancy field turns by 0.90-1.00 ``theta``, which is taken
    as the estimate. A wrong plane spacing is a scaling along the axis of the turn: it
    commutes with the turn and stays invisible. Woltring & Huiskes (1990), SMAC
    section; Selvik (1974).
    """
    if not tolerance_mm > 0.0:
        raise CalibrationError(f"tolerance_mm must be positive, got {tolerance_mm}")
    X, upper = _split_planes(cage_points)
    uv1 = _image_stack(image_points_1, X.shape[0], "image_points_1")
    uv2 = _image_stack(image_points_2, X.shape[0], "image_points_2")
    if uv1.shape[0] != uv2.shape[0]:
        raise CalibrationError(
            f"image_points_1 has {uv1.shape[0]} cameras, image_points_2 {uv2.shape[0]}"
        )
    if uv1.shape[0] < 2:
        raise CalibrationError(
            "the rotation check reconstructs the cage in 3-D: it needs at least 2 cameras, "
            f"got {uv1.shape[0]}"
        )
    first = cage_calibrate(X, uv1, distortion=distortion, image_size=image_size)
    second = cage_calibrate(X, uv2, distortion=distortion, image_size=image_size)
    d12, R12 = _cage_frame_discrepancy(X, upper, _triangulate(first.rig.cameras, uv2))
    d21, _ = _cage_frame_discrepancy(X, upper, _triangulate(second.rig.cameras, uv1))
    turn = float(np.degrees(np.arccos(np.clip((np.trace(R12) - 1.0) / 2.0, -1.0, 1.0))))
    # For a near half turn, R + I ~ 2 a a' (a the axis): its largest column gives a.
    S = R12 + R12.T + (1.0 - np.trace(R12)) * np.eye(3)
    axis = S[:, int(np.argmax(np.diag(S)))]
    tilt = float(np.degrees(np.arccos(min(1.0, abs(axis[2]) / np.linalg.norm(axis)))))
    if abs(turn - 180.0) > HALF_TURN_TOLERANCE_DEG or tilt > HALF_TURN_TOLERANCE_DEG:
        raise CalibrationError(
            f"the cage was turned by {turn:.1f} degrees about an axis {tilt:.1f} degrees "
            "from the normal of its planes: the rotation check needs a turn of about 180 "
            "degrees about that normal"
        )
    disc = 0.5 * (d12 + d21)
    norm = np.linalg.norm(disc, axis=1)
    finite = np.isfinite(norm)
    rms = float(np.sqrt(np.mean(norm[finite] ** 2)))
    worst = int(np.flatnonzero(finite)[np.argmax(norm[finite])])
    up = upper & finite
    shift, phi = _upper_plane_error(X[up, :2], disc[up, :2])
    corrected = X.copy()
    centre = X[upper, :2].mean(axis=0)
    c, s = np.cos(phi), np.sin(phi)
    rel = X[upper, :2] - centre
    corrected[upper, :2] = centre + rel @ np.array([[c, s], [-s, c]]) + shift
    passed = bool(norm[worst] <= tolerance_mm)
    verdict = (
        f"{'passed' if passed else 'failed'}: largest discrepancy {norm[worst]:.3g} mm at "
        f"marker {worst} ({'upper' if upper[worst] else 'lower'} plane), RMS {rms:.3g} mm, "
        f"tolerance {tolerance_mm:g} mm; upper plane apparently off by "
        f"({shift[0]:.3g}, {shift[1]:.3g}) mm and turned by {np.degrees(phi):.3g} degrees"
    )
    return RotationCheck(
        discrepancy_mm=disc,
        discrepancy_norm_mm=norm,
        rms_mm=rms,
        max_mm=float(norm[worst]),
        upper_plane_shift_mm=shift,
        upper_plane_rotation_deg=float(np.degrees(phi)),
        corrected_cage_points=corrected,
        turn_deg=turn,
        axis_tilt_deg=tilt,
        tolerance_mm=float(tolerance_mm),
        passed=passed,
        verdict=verdict,
        first=first,
        second=second,
    )
