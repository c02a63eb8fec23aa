"""Yeadon's orientation angles: somersault, tilt, twist; elevation, abduction, rotation.

Yeadon (1990), *The simulation of aerial movement - I* (shared/seeds/001_...): the
body frame f is brought from the reference frame i by rotations through somersault
``phi`` about f1, tilt ``theta`` about f2 and twist ``psi`` about f3, so
``S_fi = R1(-phi) R2(-theta) R3(-psi)``; a limb frame a is brought from its parent
frame c by ``-delta`` (elevation) about a1, ``-epsilon`` (abduction) about a2 and
``psi`` (rotation) about a3, so ``S_ac = R1(delta) R2(epsilon) R3(-psi)``. The
columns of ``S`` are the moving frame's unit vectors in the fixed frame.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from spotlab.kinematics.errors import KinematicsError

__all__ = [
    "OrientationAngles",
    "SegmentAngles",
    "limb_axes",
    "orientation_angles",
    "orientation_matrix",
    "segment_angles",
    "segment_angles_from_joints",
    "segment_matrix",
]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

#: Frames whose middle-angle cosine is below this are flagged as singular (gimbal lock).
SINGULAR_TOL = 1e-6


@dataclass(frozen=True)
class OrientationAngles:
    """Somersault, tilt and twist (rad), each of shape (...).

    Attributes
    ----------
    somersault : ndarray
        ``phi`` in (-pi, pi].
    tilt : ndarray
        ``theta`` in [-pi/2, pi/2].
    twist : ndarray
        ``psi`` in (-pi, pi].
    cos_tilt : ndarray
        ``cos theta``: the distance from the singularity.
    singular : ndarray of bool
        ``cos theta < singular_tol``: somersault and twist are indeterminate (only
        their sum or difference is defined); there twist is set to 0 and somersault
        carries the whole rotation, so the angles still give back the matrix.
    """

    somersault: FloatArray
    tilt: FloatArray
    twist: FloatArray
    cos_tilt: FloatArray
    singular: BoolArray


@dataclass(frozen=True)
class SegmentAngles:
    """Elevation, abduction and rotation of a segment in its parent frame (rad), shape (...).

    Attributes
    ----------
    elevation : ndarray
        ``delta`` in (-pi, pi], in the sagittal plane.
    abduction : ndarray
        ``epsilon`` in [-pi/2, pi/2], away from the sagittal plane.
    rotation : ndarray
        ``psi`` in (-pi, pi], about the segment's long axis.
    cos_abduction : ndarray
        ``cos epsilon``: the distance from the singularity.
    singular : ndarray of bool
        ``cos epsilon < singular_tol`` (rotation set to 0, elevation carries the rest),
        or, from joint centres, a straight limb whose plane is undefined.
    """

    elevation: FloatArray
    abduction: FloatArray
    rotation: FloatArray
    cos_abduction: FloatArray
    singular: BoolArray


def _rotations(axes: Any, what: str) -> FloatArray:
    S = np.asarray(axes, dtype=np.float64)
    if S.ndim < 2 or S.shape[-2:] != (3, 3):
        raise KinematicsError(f"{what} must have shape (..., 3, 3), got {S.shape}")
    finite = np.all(np.isfinite(S), axis=(-2, -1))
    if np.any(np.isinf(S)):
        raise KinematicsError(f"{what} holds infinite values (use NaN for missing frames)")
    good = np.where(finite[..., None, None], S, np.eye(3))
    err = np.max(np.abs(np.swapaxes(good, -1, -2) @ good - np.eye(3)), axis=(-2, -1))
    if np.any(err > 1e-6):
        raise KinematicsError(
            f"{what} are not orthonormal (max |S'S - I| = {float(np.max(err)):.3g}): "
            "the columns must be unit axes at right angles"
        )
    if np.any(np.linalg.det(good) < 0.0):
        raise KinematicsError(f"{what} include a left-handed frame (det < 0)")
    return S


def _decompose_xyz(
    S: FloatArray, tol: float
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, BoolArray]:
    """``S = Rx(a) Ry(b) Rz(c)`` (right-hand rotations) -> a, b, c, cos b, singular."""
    cb = np.hypot(S[..., 0, 0], S[..., 0, 1])
    b = np.arctan2(S[..., 0, 2], cb)
    a = np.arctan2(-S[..., 1, 2], S[..., 2, 2])
    c = np.arctan2(-S[..., 0, 1], S[..., 0, 0])
    singular = cb < tol
    # at b = +-pi/2 only a + c (or a - c) is defined: put it all in a, c = 0
    sb = np.sign(S[..., 0, 2])
    a_lock = np.arctan2(sb * S[..., 1, 0], S[..., 1, 1])
    a = np.where(singular, a_lock, a)
    c = np.where(singular, 0.0, c)
    return a, b, c, cb, singular


def _xyz_matrix(a: Any, b: Any, c: Any) -> FloatArray:
    a, b, c = np.broadcast_arrays(*(np.asarray(v, dtype=np.float64) for v in (a, b, c)))
    ca, sa, cb, sb, cc, sc = np.cos(a), np.sin(a), np.cos(b), np.sin(b), np.cos(c), np.sin(c)
    rows = [
        [cb * cc, -cb * sc, sb],
        [ca * sc + sa * sb * cc, ca * cc - sa * sb * sc, -sa * cb],
        [sa * sc - ca * sb * cc, sa * cc + ca * sb * sc, ca * cb],
    ]
    return np.stack([np.stack(r, axis=-1) for r in rows], axis=-2)


def orientation_angles(axes: Any, *, singular_tol: float = SINGULAR_TOL) -> OrientationAngles:
    r"""Somersault, tilt and twist of a body frame (Yeadon 1990).

    Parameters
    ----------
    axes : array_like, shape (..., 3, 3)
        ``S_fi``: columns are the body axes f1, f2, f3 in the reference frame i
        (a rotation matrix); NaN frames give NaN angles.
    singular_tol : float
        Flag frames with ``cos(tilt)`` below this.

    Returns
    -------
    OrientationAngles

    Raises
    ------
    KinematicsError
        Wrong shape, infinite values, or axes that are not a right-handed orthonormal
        triad.

    Notes
    -----
    :math:`S_{fi} = R_1(-\phi) R_2(-\theta) R_3(-\psi)` gives
    :math:`\sin\theta = F3(1)`, :math:`\tan\phi = -F3(2)/F3(3)`,
    :math:`\tan\psi = -F2(1)/F1(1)` (Yeadon 1990), evaluated with ``arctan2`` so that
    no division by :math:`\cos\theta` is needed. Singular at :math:`\theta = \pm\pi/2`.

    Examples
    --------
    >>> import numpy as np
    >>> S = orientation_matrix(0.3, -0.2, 1.0)
    >>> a = orientation_angles(S)
    >>> [round(float(v), 12) for v in (a.somersault, a.tilt, a.twist)]
    [0.3, -0.2, 1.0]
    """
    S = _rotations(axes, "axes")
    a, b, c, cb, singular = _decompose_xyz(S, singular_tol)
    return OrientationAngles(a, b, c, cb, singular & np.isfinite(cb))


def orientation_matrix(somersault: Any, tilt: Any, twist: Any) -> FloatArray:
    """``S_fi`` of somersault, tilt and twist (rad), broadcast, shape (..., 3, 3)."""
    return _xyz_matrix(somersault, tilt, twist)


def segment_angles(axes: Any, *, singular_tol: float = SINGULAR_TOL) -> SegmentAngles:
    r"""Elevation, abduction and rotation of a segment frame in its parent frame.

    Parameters
    ----------
    axes : array_like, shape (..., 3, 3)
        ``S_ac``: columns are the segment axes a1, a2, a3 in the parent frame c.
    singular_tol : float
        Flag frames with ``cos(abduction)`` below this.

    Returns
    -------
    SegmentAngles

    Raises
    ------
    KinematicsError
        As :func:`orientation_angles`.

    Notes
    -----
    :math:`S_{ac} = R_1(\delta) R_2(\varepsilon) R_3(-\psi)` gives
    :math:`\sin\varepsilon = -A3(1)`, :math:`\tan\delta = A3(2)/A3(3)`,
    :math:`\tan\psi = -A2(1)/A1(1)` (Yeadon 1990). Singular at
    :math:`\varepsilon = \pm\pi/2` (arm perpendicular to the sagittal plane).
    """
    S = _rotations(axes, "axes")
    a, b, c, cb, singular = _decompose_xyz(S, singular_tol)
    return SegmentAngles(-a, -b, c, cb, singular & np.isfinite(cb))


def segment_matrix(elevation: Any, abduction: Any, rotation: Any) -> FloatArray:
    """``S_ac`` of elevation, abduction and rotation (rad), broadcast, shape (..., 3, 3)."""
    return _xyz_matrix(-np.asarray(elevation), -np.asarray(abduction), rotation)


def limb_axes(
    proximal: Any, joint: Any, distal: Any, *, straight_tol: float = 1e-3
) -> tuple[FloatArray, BoolArray]:
    """Axes of a limb segment from three joint centres (e.g. shoulder, elbow, wrist).

    Parameters
    ----------
    proximal, joint, distal : array_like, shape (..., 3)
        Joint centres (mm): the segment runs from ``joint`` to ``proximal``; ``distal``
        is the far end of the next segment (the wrist for the upper arm).
    straight_tol : float
        Flag frames where the sine of the angle at ``joint`` is below this.

    Returns
    -------
    axes : ndarray, shape (..., 3, 3)
        Columns a1, a2, a3: ``a3`` from joint to proximal (the long axis),
        ``a1`` normal to the plane of the three centres, along
        ``(distal - joint) x (proximal - joint)`` (the flexion axis of the joint),
        ``a2 = a3 x a1``. NaN where flagged.
    straight : ndarray of bool, shape (...)
        The three centres are (nearly) collinear: the limb is straight and its plane,
        hence ``a1``, ``a2`` and the rotation angle, is undefined.

    Raises
    ------
    KinematicsError
        Shapes that do not broadcast to (..., 3), infinite values, or coincident
        centres.

    Notes
    -----
    With the parent frame's c3 pointing up the trunk and c2 forward, a hanging upper
    arm with the forearm pointing forward gives ``a = c`` (all angles 0). Yeadon
    (1990) defines the upper-arm frame from S, E and W in his Fig. 3; the seed text
    does not carry the formula, so this construction is spotlab's reading of it.
    """
    try:
        p, j, d = np.broadcast_arrays(
            *(np.asarray(v, dtype=np.float64) for v in (proximal, joint, distal))
        )
    except ValueError as exc:
        raise KinematicsError(f"joint centres do not broadcast together: {exc}") from None
    if p.ndim == 0 or p.shape[-1] != 3:
        raise KinematicsError(f"joint centres must have shape (..., 3), got {p.shape}")
    if np.any(np.isinf(p) | np.isinf(j) | np.isinf(d)):
        raise KinematicsError("joint centres hold infinite values (use NaN for missing)")
    u = p - j
    v = d - j
    lu = np.linalg.norm(u, axis=-1)
    lv = np.linalg.norm(v, axis=-1)
    if np.any((lu == 0.0) | (lv == 0.0)):
        raise KinematicsError("two joint centres coincide: the segment has no length")
    n = np.cross(v, u)
    sin_angle = np.linalg.norm(n, axis=-1) / (lu * lv)
    straight = sin_angle < straight_tol
    a3 = u / lu[..., None]
    with np.errstate(invalid="ignore", divide="ignore"):
        a1 = n / np.linalg.norm(n, axis=-1, keepdims=True)
    a2 = np.cross(a3, a1)
    axes = np.stack([a1, a2, a3], axis=-1)
    axes = np.where(straight[..., None, None], np.nan, axes)
    return axes, straight


def segment_angles_from_joints(
    parent_axes: Any,
    proximal: Any,
    joint: Any,
    distal: Any,
    *,
    singular_tol: float = SINGULAR_TOL,
    straight_tol: float = 1e-3,
) -> SegmentAngles:
    """Elevation, abduction and rotation of a limb from joint centres (Yeadon 1990).

    Parameters
    ----------
    parent_axes : array_like, shape (..., 3, 3)
        Columns c1, c2, c3 of the parent (e.g. chest) frame in world coordinates.
    proximal, joint, distal : array_like, shape (..., 3)
        Joint centres in world coordinates (mm), see :func:`limb_axes`.
    singular_tol, straight_tol : float
        See :func:`segment_angles` and :func:`limb_axes`.

    Returns
    -------
    SegmentAngles
        ``singular`` marks both gimbal lock and a straight limb; angles are NaN for a
        straight limb (no plane, no rotation angle), never a guess.

    Notes
    -----
    ``A_k(j) = a_k . c_j``, i.e. ``S_ac = C' A`` with ``C`` and ``A`` the frames'
    axes in world coordinates (Yeadon 1990).
    """
    C = _rotations(parent_axes, "parent_axes")
    A, straight = limb_axes(proximal, joint, distal, straight_tol=straight_tol)
    S = np.swapaxes(C, -1, -2) @ A
    angles = segment_angles(S, singular_tol=singular_tol)
    return SegmentAngles(
        angles.elevation,
        angles.abduction,
        angles.rotation,
        angles.cos_abduction,
        angles.singular | straight,
    )
