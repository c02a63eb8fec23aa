"""Markers from linear sensors: each 1-D reading is a plane; >= 3 planes meet in the marker.

A linear detector (CCD line or 1-D lateral photodiode) behind a cylindrical lens
measures one image coordinate: the marker lies in the plane through the lens axis
and that line of the detector (Woltring & Huiskes 1990: "dedicated line scanners may
provide 1-D information per sensor"; WATSMART, Macellari 1983, Mesqui et al. 1985).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from spotlab.core.errors import ReconstructionError

__all__ = ["PlaneIntersection", "intersect_planes", "linear_sensor_plane"]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


@dataclass(frozen=True)
class PlaneIntersection:
    """Least-squares intersections of planes, one per point.

    Attributes
    ----------
    points : ndarray, shape (..., 3)
        The point nearest to its planes (mm); NaN where flagged.
    residuals : ndarray, shape (..., K)
        Signed distance of the point from each plane (mm); NaN for missing planes.
    rms : ndarray, shape (...)
        Weighted RMS of the distances (mm).
    condition : ndarray, shape (...)
        Condition number of the normal matrix ``sum w n n'`` (1 for three orthogonal
        planes; large when the plane normals are nearly coplanar).
    n_planes : ndarray of int, shape (...)
        Planes used.
    ill_conditioned : ndarray of bool, shape (...)
        Fewer than 3 planes or ``condition > max_condition``: the planes do not fix
        the point (their normals are nearly coplanar, e.g. nearly parallel planes).
    """

    points: FloatArray
    residuals: FloatArray
    rms: FloatArray
    condition: FloatArray
    n_planes: NDArray[np.int64]
    ill_conditioned: BoolArray


def intersect_planes(
    normals: Any, offsets: Any, weights: Any = None, *, max_condition: float = 1e8
) -> PlaneIntersection:
    r"""The point nearest (in the weighted least-squares sense) to >= 3 planes.

    Parameters
    ----------
    normals : array_like, shape (..., K, 3)
        Plane normals (any length, not zero); NaN marks a missing plane.
    offsets : array_like, shape (..., K)
        Plane offsets: plane k holds the points ``X`` with ``n_k . X = d_k`` (mm times
        the normal's length).
    weights : array_like, shape (..., K) or (K,), optional
        Non-negative weight of each plane (inverse variance of its distance).
    max_condition : float
        Flag points whose normal matrix has a larger condition number.

    Returns
    -------
    PlaneIntersection

    Raises
    ------
    ReconstructionError
        Shapes that disagree, fewer than 3 planes per point, a zero normal, infinite
        values, negative weights, or no plane at all.

    Notes
    -----
    With unit normals :math:`\hat n_k = n_k / |n_k|` and :math:`\hat d_k = d_k / |n_k|`
    the point minimises :math:`\sum_k w_k (\hat n_k \cdot X - \hat d_k)^2`, so
    :math:`(\sum_k w_k \hat n_k \hat n_k^T) X = \sum_k w_k \hat d_k \hat n_k`, one
    3 x 3 system per point, solved for all points at once.
    """
    n = np.asarray(normals, dtype=np.float64)
    d = np.asarray(offsets, dtype=np.float64)
    if n.ndim < 2 or n.shape[-1] != 3:
        raise ReconstructionError(f"normals must have shape (..., K, 3), got {n.shape}")
    if d.shape != n.shape[:-1]:
        raise ReconstructionError(
            f"offsets must have shape {n.shape[:-1]} to match the normals, got {d.shape}"
        )
    if n.shape[-2] < 3:
        raise ReconstructionError(f"{n.shape[-2]} planes: a point needs at least 3")
    if np.any(np.isinf(n)) or np.any(np.isinf(d)):
        raise ReconstructionError("normals or offsets hold infinite values (NaN for missing)")
    if weights is None:
        w = np.ones(d.shape)
    else:
        w = np.asarray(weights, dtype=np.float64)
        try:
            w = np.broadcast_to(w, d.shape)
        except ValueError:
            raise ReconstructionError(
                f"weights must broadcast to {d.shape}, got {w.shape}"
            ) from None
        if not np.all(np.isfinite(w)) or np.any(w < 0.0):
            raise ReconstructionError("weights must be finite and >= 0")
    length = np.linalg.norm(n, axis=-1)
    if np.any(length == 0.0):
        raise ReconstructionError("a plane normal is zero: it defines no plane")
    use = np.isfinite(length) & np.isfinite(d) & (w > 0.0)
    if not np.any(use):
        raise ReconstructionError("no plane: normals or offsets are NaN everywhere")
    u = np.where(use[..., None], n / np.where(use, length, 1.0)[..., None], 0.0)
    du = np.where(use, d / np.where(use, length, 1.0), 0.0)
    w = np.where(use, w, 0.0)
    N = np.einsum("...k,...ki,...kj->...ij", w, u, u)
    rhs = np.einsum("...k,...k,...ki->...i", w, du, u)
    ev = np.linalg.eigvalsh(N)
    with np.errstate(divide="ignore", invalid="ignore"):
        condition = np.where(ev[..., 0] > 0.0, ev[..., -1] / ev[..., 0], np.inf)
    n_planes = use.sum(axis=-1).astype(np.int64)
    bad = (n_planes < 3) | ~(condition <= max_condition)
    safe = np.where(bad[..., None, None], np.eye(3), N)
    X = np.linalg.solve(safe, rhs[..., None])[..., 0]
    X = np.where(bad[..., None], np.nan, X)
    residuals = np.where(use, np.einsum("...ki,...i->...k", u, X) - du, np.nan)
    wsum = np.where(bad, 1.0, w.sum(axis=-1))
    rms = np.sqrt(np.nansum(w * np.nan_to_num(residuals) ** 2, axis=-1) / wsum)
    rms = np.where(bad, np.nan, rms)
    return PlaneIntersection(X, residuals, rms, condition, n_planes, bad)


def linear_sensor_plane(
    reading: Any, *, focal: float, principal: float, R: Any, t: Any, axis: int = 0
) -> tuple[FloatArray, FloatArray]:
    """The plane in which a marker lies, from one reading of a linear sensor.

    Parameters
    ----------
    reading : array_like, shape (...)
        Position of the light line on the detector (px or mm, like ``focal``);
        NaN gives a NaN (missing) plane.
    focal : float
        Principal distance, in the units of ``reading``.
    principal : float
        Reading of the optical axis (principal point), same units.
    R : array_like, shape (3, 3)
        Rotation world -> sensor frame (``x_s = R X + t``), det +1.
    t : array_like, shape (3,)
        Translation (mm).
    axis : {0, 1}
        Sensor-frame axis the detector measures along (0: x, the cylindrical lens'
        axis along y; 1: y, lens axis along x).

    Returns
    -------
    normal : ndarray, shape (..., 3)
        Unit normal of the plane in world coordinates.
    offset : ndarray, shape (...)
        Offset (mm): the plane is ``normal . X = offset``; feed both to
        :func:`intersect_planes`.

    Raises
    ------
    ReconstructionError
        A non-positive focal length, a bad rotation, or an axis other than 0 or 1.

    Notes
    -----
    The sensor measures ``r = f x_s[axis] / x_s[2] + r0``, so the marker lies in the
    plane ``f x_s[axis] - (r - r0) x_s[2] = 0`` through the lens axis: in the sensor
    frame its normal is ``m = f e_axis - (r - r0) e_z``; in the world
    ``(R' m) . X = -m . t``.
    """
    if axis not in (0, 1):
        raise ReconstructionError(f"axis must be 0 or 1, got {axis!r}")
    if not (np.isfinite(focal) and focal > 0.0):
        raise ReconstructionError(f"focal must be positive and finite, got {focal!r}")
    Rm = np.asarray(R, dtype=np.float64)
    tv = np.asarray(t, dtype=np.float64)
    if Rm.shape != (3, 3) or tv.shape != (3,):
        raise ReconstructionError(f"R must be (3, 3) and t (3,), got {Rm.shape} and {tv.shape}")
    if not (np.allclose(Rm @ Rm.T, np.eye(3), atol=1e-6) and np.linalg.det(Rm) > 0.0):
        raise ReconstructionError("R is not a rotation (orthonormal, det +1)")
    r = np.asarray(reading, dtype=np.float64) - principal
    m = np.zeros((*r.shape, 3))
    m[..., axis] = focal
    m[..., 2] = -r
    m /= np.linalg.norm(m, axis=-1, keepdims=True)
    return m @ Rm, -(m @ tv)
