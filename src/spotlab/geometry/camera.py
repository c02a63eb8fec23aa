"""Pinhole camera with Brown distortion, and its identification with the 11 DLT parameters."""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.linalg

from spotlab.core.errors import CalibrationError
from spotlab.geometry import _checks
from spotlab.geometry._checks import FloatArray
from spotlab.geometry.distortion import distort_normalized, undistort_normalized

__all__ = ["Camera", "flip_dlt_v"]


def flip_dlt_v(L: Any, height: float) -> FloatArray:
    """DLT parameters for the image row axis turned over: ``v' = height - v``.

    Parameters
    ----------
    L : array_like, shape (11,)
        DLT parameters for one image convention.
    height : float
        Image height (px).

    Returns
    -------
    ndarray, shape (11,)
        The parameters for the other convention; applying the function twice gives
        ``L`` back. DLTdv and easyWand measure ``v`` upwards from the bottom edge,
        spotlab (like OpenCV) downwards from the top.

    Notes
    -----
    ``v' = height - (L5 X + L6 Y + L7 Z + L8) / D`` with ``D = L9 X + L10 Y + L11 Z + 1``,
    so ``L5..L7' = height L9..L11 - L5..L7`` and ``L8' = height - L8``.
    """
    out = _checks.finite_array(L, (11,), "L (DLT parameters)")
    out[4:7] = height * out[8:11] - out[4:7]
    out[7] = height - out[7]
    return out


class Camera:
    """A calibrated camera: intrinsics ``K``, distortion ``dist``, pose ``R``, ``t``.

    Parameters
    ----------
    K : array_like, shape (3, 3)
        Intrinsic matrix ``[[fx, s, cx], [0, fy, cy], [0, 0, 1]]`` in pixels: separate
        principal distances per axis ``fx, fy > 0``, shear ``s``, principal point.
    dist : array_like, shape (5,) or (4,) or None
        Distortion in OpenCV order ``(k1, k2, p1, p2, k3)``; 4 values mean ``k3 = 0``.
    R : array_like, shape (3, 3)
        Rotation from world to camera frame, orthonormal with determinant +1.
    t : array_like, shape (3,)
        Translation (world units, mm in spotlab): ``x_cam = R @ X + t``.
    size : (int, int)
        Image ``(width, height)`` in pixels.
    name : str
        Camera label.

    Raises
    ------
    CalibrationError
        For any input that is not a valid camera, naming which and why.

    Notes
    -----
    Projection: ``x_cam = R X + t``; ``(x, y) = (x_cam/z_cam, y_cam/z_cam)``; Brown
    distortion (:mod:`spotlab.geometry.distortion`); ``u = fx x_d + s y_d + cx``,
    ``v = fy y_d + cy``. This is OpenCV's model exactly when ``s = 0`` (OpenCV's
    ``projectPoints`` ignores ``K[0, 1]``). The collinearity condition is Woltring &
    Huiskes (1990) Eq. 1; the linear intrinsics are Eq. 11 with the shear in the
    upper triangle (Hartley & Zisserman's convention) rather than Woltring's lower one.

    Examples
    --------
    >>> import numpy as np
    >>> from spotlab.geometry import Camera
    >>> K = [[1000.0, 0.0, 320.0], [0.0, 1000.0, 240.0], [0.0, 0.0, 1.0]]
    >>> cam = Camera(K, None, np.eye(3), [0.0, 0.0, 2000.0], (640, 480), name="front")
    >>> cam.project([[100.0, -50.0, 0.0]])
    array([[370., 215.]])
    >>> float(cam.center[2])  # the perspective centre, 2 m behind the origin
    -2000.0
    >>> back = Camera.from_dlt(cam.to_dlt(), cam.size)
    >>> bool(np.allclose(back.K, cam.K) and np.allclose(back.t, cam.t))
    True
    """

    __slots__ = ("K", "R", "dist", "name", "size", "t")

    def __init__(
        self,
        K: Any,
        dist: Any,
        R: Any,
        t: Any,
        size: Any,
        name: str = "",
    ) -> None:
        self.K: FloatArray = _checks.intrinsic_matrix(K)
        self.dist: FloatArray = _checks.distortion_vector(dist)
        self.R: FloatArray = _checks.rotation_matrix(R)
        self.t: FloatArray = _checks.finite_array(t, (3,), "t (translation)").reshape(3)
        self.size: tuple[int, int] = _checks.image_size(size)
        self.name = str(name)
        for arr in (self.K, self.dist, self.R, self.t):
            arr.flags.writeable = False

    def __repr__(self) -> str:
        fx, fy, cx, cy = self.K[0, 0], self.K[1, 1], self.K[0, 2], self.K[1, 2]
        return (
            f"Camera(name={self.name!r}, size={self.size}, fx={fx:.6g}, fy={fy:.6g}, "
            f"cx={cx:.6g}, cy={cy:.6g}, center={np.array2string(self.center, precision=4)})"
        )

    @property
    def center(self) -> FloatArray:
        """Perspective centre in world coordinates, shape (3,): ``-R' t``."""
        return -self.R.T @ self.t

    @property
    def projection_matrix(self) -> FloatArray:
        """``K [R | t]``, shape (3, 4) (distortion not included)."""
        return self.K @ np.column_stack([self.R, self.t])

    def project(self, X: Any) -> FloatArray:
        """Image coordinates of world points.

        Parameters
        ----------
        X : array_like, shape (..., 3)
            World points (mm).

        Returns
        -------
        ndarray, shape (..., 2)
            Pixel coordinates ``(u, v)``; NaN where the point is NaN or not in front of
            the camera (``z_cam <= 0``).
        """
        X = _checks.points(X, 3, "X (world points)")
        xc = X @ self.R.T + self.t
        z = xc[..., 2:3]
        with np.errstate(divide="ignore", invalid="ignore"):
            xy = np.where(z > 0.0, xc[..., :2] / z, np.nan)
        return self._to_pixels(distort_normalized(xy, self.dist))

    def _to_pixels(self, xy: FloatArray) -> FloatArray:
        K = self.K
        u = K[0, 0] * xy[..., 0] + K[0, 1] * xy[..., 1] + K[0, 2]
        v = K[1, 1] * xy[..., 1] + K[1, 2]
        return np.stack([u, v], axis=-1)

    def _from_pixels(self, uv: FloatArray) -> FloatArray:
        K = self.K
        y = (uv[..., 1] - K[1, 2]) / K[1, 1]
        x = (uv[..., 0] - K[0, 2] - K[0, 1] * y) / K[0, 0]
        return np.stack([x, y], axis=-1)

    def normalize(self, uv: Any, *, tol: float = 1e-12, max_iter: int = 50) -> FloatArray:
        """Ideal normalised coordinates ``(x_cam/z_cam, y_cam/z_cam)`` of pixels.

        Parameters
        ----------
        uv : array_like, shape (..., 2)
            Observed (distorted) pixel coordinates; NaN stays NaN.
        tol, max_iter
            See :func:`spotlab.geometry.distortion.undistort_normalized`.

        Returns
        -------
        ndarray, shape (..., 2)
            The ray direction of each pixel is ``(x, y, 1)`` in the camera frame.

        Raises
        ------
        CalibrationError
            When the distortion inversion does not converge.
        """
        uv = _checks.points(uv, 2, "uv (image points)")
        return undistort_normalized(self._from_pixels(uv), self.dist, tol=tol, max_iter=max_iter)

    def undistort(self, uv: Any, *, tol: float = 1e-12, max_iter: int = 50) -> FloatArray:
        """Pixel coordinates with the lens distortion removed (same ``K``), shape (..., 2).

        Inverse of the distortion step of :meth:`project`, solved by Newton iteration
        with a convergence check; raises :class:`CalibrationError` if it fails.
        """
        return self._to_pixels(self.normalize(uv, tol=tol, max_iter=max_iter))

    def distort(self, uv: Any) -> FloatArray:
        """Apply the lens distortion to ideal pixel coordinates, shape (..., 2)."""
        uv = _checks.points(uv, 2, "uv (image points)")
        return self._to_pixels(distort_normalized(self._from_pixels(uv), self.dist))

    def to_dlt(self, *, v_up: bool = False) -> FloatArray:
        """The 11 DLT parameters of the linear part of the camera (distortion ignored).

        Parameters
        ----------
        v_up : bool
            Give the parameters for image rows counted upwards from the bottom edge
            (DLTdv, easyWand): ``v_up = height - v`` (see :func:`flip_dlt_v`).

        Returns
        -------
        ndarray, shape (11,)
            ``L`` with ``u = (L1 X + L2 Y + L3 Z + L4) / (L9 X + L10 Y + L11 Z + 1)``
            and ``v = (L5 X + L6 Y + L7 Z + L8) / (same)`` (Woltring Eq. 4).

        Raises
        ------
        CalibrationError
            When the world origin lies in the camera's principal plane (``t_z = 0``):
            the DLT's normalisation ``L12 = 1`` is then undefined (Woltring's advice:
            put the origin inside the observed volume).

        Notes
        -----
        ``P = K [R | t]`` and ``L = P / P[2, 3]`` read row by row, without ``P[2, 3]``
        (Woltring & Huiskes 1990, Eq. 15).
        """
        P = self.projection_matrix
        if abs(P[2, 3]) <= 1e-12 * float(np.max(np.abs(P))):
            raise CalibrationError(
                "to_dlt: the world origin lies in the camera's principal plane (t_z = 0); "
                "the DLT normalisation L12 = 1 is undefined"
            )
        L = (P / P[2, 3]).ravel()[:11].copy()
        return flip_dlt_v(L, self.size[1]) if v_up else L

    @classmethod
    def from_dlt(cls, L: Any, size: Any, name: str = "", *, v_up: bool = False) -> Camera:
        """The camera of 11 DLT parameters, by RQ decomposition.

        Parameters
        ----------
        L : array_like, shape (11,)
            DLT parameters (see :meth:`to_dlt`).
        size : (int, int)
            Image ``(width, height)`` in pixels.
        name : str
            Camera label.
        v_up : bool
            ``L`` is for image rows counted upwards from the bottom edge (DLTdv,
            easyWand); it is converted with :func:`flip_dlt_v` first. Without it such
            coefficients give a camera with the scene behind it (``project`` -> NaN):
            no proper rotation maps a right-handed world onto left-handed image axes.

        Returns
        -------
        Camera
            With ``dist = 0``; ``Camera.from_dlt(L, size).to_dlt()`` equals ``L``.

        Raises
        ------
        CalibrationError
            When ``L`` is not finite or its left 3x3 block is singular (no camera).

        Notes
        -----
        ``P = [[L1..L4], [L5..L8], [L9, L10, L11, 1]]`` equals ``lambda K [R | t]``.
        The sign of ``lambda`` is that of ``det P[:, :3]`` (so that ``det R = +1``); the
        RQ decomposition ``P[:, :3] / lambda = K R`` with positive diagonal of ``K``
        gives ``K`` (scaled so ``K[2, 2] = 1``) and ``R``; then ``t = K^-1 P[:, 3] /
        lambda`` (Woltring & Huiskes 1990, Eq. 15: "orthogonal triangularization and
        back-substitution").
        """
        L = _checks.finite_array(L, (11,), "L (DLT parameters)")
        if v_up:
            L = flip_dlt_v(L, _checks.image_size(size)[1])
        P = np.append(L, 1.0).reshape(3, 4)
        M = P[:, :3]
        det = float(np.linalg.det(M))
        scale = float(np.max(np.abs(M))) ** 3
        if not abs(det) > 1e-12 * scale:
            raise CalibrationError(
                "from_dlt: the DLT parameters are degenerate (det of the 3x3 part is 0): "
                "no camera has them"
            )
        sign = 1.0 if det > 0.0 else -1.0
        K_raw, Q = scipy.linalg.rq(sign * M)
        D = np.diag(np.sign(np.diag(K_raw)))
        K_raw = K_raw @ D
        Q = D @ Q
        lam = K_raw[2, 2]
        K = K_raw / lam
        t = np.linalg.solve(K, sign * P[:, 3] / lam)
        return cls(K, None, Q, t, size, name)
