"""Viewing rays of image points: fast undistortion of many observations.

The inverse of the Brown model is the expensive part of triangulating many points. The
geometry layer's :meth:`Camera.normalize` iterates Newton's method point by point until
each one converges; here each camera's seen observations (gathered into one array, the
lens parameters as Python floats) take the same short sequence of steps:

1. a start value from an approximate inverse fitted once per lens (cached): in the
   distorted coordinates ``(x, y)`` with ``rho = x^2 + y^2``,
   ``x_u = x g(rho) + a(rho) (p1 x y + p2 x^2) + p2 rho h(rho)`` and
   ``y_u = y g(rho) + a(rho) (p2 x y + p1 y^2) + p1 rho h(rho)`` with polynomials
   ``g`` (degree 6), ``a`` and ``h`` (degree 3) fitted by least squares to exact pairs
   over the image and a 3 % margin (the radial inverse, and the tangential terms to
   first order in ``p1, p2``); on the reference rig it is within 2e-6 of the inverse
   there;
2. one Newton step with the 2x2 Jacobian inverted in closed form.

Newton converges quadratically: a step of at most ``_STEP_TOL`` (1e-6) leaves an error
of the order of its square, and measured on the reference rig a step from the fitted
start leaves less than 2e-12 (normalised units, 2e-9 px). Observations whose step
exceeds ``_STEP_TOL`` (outside the fitted region; 0-0.3 % of an image) take further
steps; those still not converging, or on the folded branch of the polynomial, go to
:meth:`Camera.normalize`, which converges or raises.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from spotlab.core.errors import CalibrationError, ReconstructionError
from spotlab.geometry import Camera

FloatArray = NDArray[np.float64]
Coefficients = tuple[FloatArray | float, ...]

#: Largest Newton step (normalised units) accepted as converged: the error left after
#: it is about its square (below 1e-12, 1e-9 px).
_STEP_TOL = 1e-6
_EXTRA_STEPS = 6  # for the few observations the first step leaves short
#: Degrees of the start polynomials g, a, h and the margin (fraction of the image size)
#: of the region they are fitted on.
_DEGREES = (6, 3, 3)
_MARGIN = 0.03
_GRID = (64, 52)  # fit samples across the image (width, height)


def brown(x: FloatArray, y: FloatArray, dist: FloatArray) -> tuple[FloatArray, ...]:
    """Brown distortion of ideal normalised coordinates and its Jacobian.

    Parameters
    ----------
    x, y : ndarray, shape (N,)
        Ideal normalised coordinates.
    dist : ndarray, shape (5,)
        ``(k1, k2, p1, p2, k3)`` (OpenCV order).

    Returns
    -------
    xd, yd, j00, j01, j11 : ndarray, shape (N,)
        Distorted coordinates and the symmetric Jacobian ``d(xd, yd) / d(x, y)``
        (``j10 = j01``), the model of :func:`spotlab.geometry.distort_normalized`.
    """
    return _brown(x, y, tuple(float(c) for c in dist))


def _brown(x: FloatArray, y: FloatArray, k: Coefficients) -> tuple[FloatArray, ...]:
    """:func:`brown` with coefficients ``(k1, k2, p1, p2, k3)`` that broadcast against x."""
    k1, k2, p1, p2, k3 = k
    xx, yy, xy = x * x, y * y, x * y
    r2 = xx + yy
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    slope = 2.0 * (k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2))  # 2 d radial / d r^2
    xd = x * radial + 2.0 * p1 * xy + p2 * (r2 + 2.0 * xx)
    yd = y * radial + p1 * (r2 + 2.0 * yy) + 2.0 * p2 * xy
    j00 = radial + xx * slope + 2.0 * p1 * y + 6.0 * p2 * x
    j01 = xy * slope + 2.0 * (p1 * x + p2 * y)
    j11 = radial + yy * slope + 6.0 * p1 * y + 2.0 * p2 * x
    return xd, yd, j00, j01, j11


def _newton_step(
    x: FloatArray, y: FloatArray, x_d: FloatArray, y_d: FloatArray, k: Coefficients
) -> FloatArray:
    """One Newton step towards ``brown(x, y) = (x_d, y_d)`` in place; returns its size
    (inf where the Jacobian is not positive definite). The terms of :func:`_brown`,
    written with in-place operations."""
    k1, k2, p1, p2, k3 = k
    xx = x * x
    yy = y * y
    xy = x * y
    r2 = xx + yy
    radial = r2 * k3
    radial += k2
    radial *= r2
    radial += k1
    radial *= r2
    radial += 1.0
    slope = r2 * (6.0 * k3)  # 2 d radial / d r^2
    slope += 4.0 * k2
    slope *= r2
    slope += 2.0 * k1
    # Residuals: x radial + 2 p1 xy + p2 (3 xx + yy) - x_d, and the same for y.
    ex = x * radial
    ex -= x_d
    ex += (2.0 * p1) * xy
    ex += (3.0 * p2) * xx
    ex += p2 * yy
    ey = y * radial
    ey -= y_d
    ey += (2.0 * p2) * xy
    ey += (3.0 * p1) * yy
    ey += p1 * xx
    j00 = xx * slope
    j00 += radial
    j00 += (2.0 * p1) * y
    j00 += (6.0 * p2) * x
    j11 = yy * slope
    j11 += radial
    j11 += (6.0 * p1) * y
    j11 += (2.0 * p2) * x
    j01 = xy * slope
    j01 += (2.0 * p1) * x
    j01 += (2.0 * p2) * y
    det = j00 * j11
    det -= j01 * j01
    ok = det > 0.0
    inv_det = 1.0 / det
    dx = j11 * ex
    dx -= j01 * ey
    dx *= inv_det
    dy = j00 * ey
    dy -= j01 * ex
    dy *= inv_det
    x -= dx
    y -= dy
    np.abs(dx, out=dx)
    np.abs(dy, out=dy)
    np.maximum(dx, dy, out=dx)
    # A Jacobian that is not positive definite: the folded branch (no unique inverse).
    j00 += j11
    ok &= j00 > 0.0
    dx[~ok] = np.inf
    return dx


def _basis(x: FloatArray, y: FloatArray, dist: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Columns of the start polynomials for x and y (distorted coordinates), (N, P)."""
    _, _, p1, p2, _ = (float(c) for c in dist)
    ng, na, nh = _DEGREES
    rho = x * x + y * y
    powers = [np.ones_like(rho)]
    for _ in range(ng):
        powers.append(powers[-1] * rho)
    tx = p1 * x * y + p2 * x * x
    ty = p2 * x * y + p1 * y * y
    bx = [x * powers[i] for i in range(ng + 1)]
    bx += [tx * powers[i] for i in range(na + 1)]
    bx += [p2 * powers[i + 1] for i in range(nh + 1)]
    by = [y * powers[i] for i in range(ng + 1)]
    by += [ty * powers[i] for i in range(na + 1)]
    by += [p1 * powers[i + 1] for i in range(nh + 1)]
    return np.stack(bx, axis=1), np.stack(by, axis=1)


@functools.lru_cache(maxsize=256)
def _start_fit(k_bytes: bytes, dist_bytes: bytes, size: tuple[int, int]) -> FloatArray:
    """Coefficients of g, a, h (lowest power first, concatenated) for one lens."""
    K = np.frombuffer(k_bytes).reshape(3, 3)
    dist = np.frombuffer(dist_bytes)
    w, h = size
    u, v = np.meshgrid(
        np.linspace(-_MARGIN * w, (1.0 + _MARGIN) * w, _GRID[0]),
        np.linspace(-_MARGIN * h, (1.0 + _MARGIN) * h, _GRID[1]),
    )
    y_d = (v.ravel() - K[1, 2]) / K[1, 1]
    x_d = (u.ravel() - K[0, 2] - K[0, 1] * y_d) / K[0, 0]
    # Ideal points near the inverse (a few plain Newton steps), then exact pairs from
    # the forward model: no pair depends on the inverse having converged.
    k = tuple(float(c) for c in dist)
    r2 = x_d * x_d + y_d * y_d
    shrink = 1.0 / (1.0 + r2 * (k[0] + r2 * (k[1] + r2 * k[4])))
    x, y = x_d * shrink, y_d * shrink
    with np.errstate(all="ignore"):
        for _ in range(8):
            step = _newton_step(x, y, x_d, y_d, k)
    good = np.isfinite(step) & np.isfinite(x) & np.isfinite(y)
    x, y = x[good], y[good]
    xd, yd, *_ = _brown(x, y, k)
    bx, by = _basis(xd, yd, dist)
    coef = np.linalg.lstsq(np.vstack([bx, by]), np.concatenate([x, y]), rcond=None)[0]
    coef.flags.writeable = False
    return np.asarray(coef)


class Lens:
    """One camera's intrinsic parameters and fitted start, as Python floats.

    Parameters
    ----------
    camera : Camera
    """

    def __init__(self, camera: Camera) -> None:
        self.camera = camera
        K = camera.K
        self.cx, self.cy = float(K[0, 2]), float(K[1, 2])
        self.skew = float(K[0, 1])
        self.fx_inv, self.fy_inv = 1.0 / float(K[0, 0]), 1.0 / float(K[1, 1])
        self.k: Coefficients = tuple(float(c) for c in camera.dist)
        self.distorted = any(self.k)
        if self.distorted:
            coef = [float(c) for c in _start_fit(K.tobytes(), camera.dist.tobytes(), camera.size)]
            ng, na, _ = _DEGREES
            self.g = coef[: ng + 1]
            self.a = coef[ng + 1 : ng + na + 2]
            self.h = coef[ng + na + 2 :]

    def normalize(self, u: FloatArray, v: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Ideal normalised coordinates of pixels.

        Parameters
        ----------
        u, v : ndarray, shape (N,)
            Pixel coordinates (finite).

        Returns
        -------
        x, y : ndarray, shape (N,)
            Ideal normalised coordinates: the ray of a pixel is ``(x, y, 1)`` in the
            camera frame.

        Raises
        ------
        ReconstructionError
            When a pixel lies where the distortion model has no inverse.
        """
        y_d = v - self.cy
        y_d *= self.fy_inv
        x_d = u - self.cx
        if self.skew:
            x_d -= self.skew * y_d
        x_d *= self.fx_inv
        if not self.distorted:
            return x_d, y_d
        x, y = self._start(x_d, y_d)
        step = _newton_step(x, y, x_d, y_d, self.k)
        slow = np.flatnonzero(~(step <= _STEP_TOL))
        if slow.size:
            self._finish(x, y, x_d, y_d, u, v, slow)
        return x, y

    def _start(self, x_d: FloatArray, y_d: FloatArray) -> tuple[FloatArray, FloatArray]:
        """The fitted approximate inverse (see the module docstring)."""
        _, _, p1, p2, _ = self.k
        xx = x_d * x_d
        yy = y_d * y_d
        xy = x_d * y_d
        rho = xx + yy
        g = _horner(rho, self.g)
        a = _horner(rho, self.a)
        h = _horner(rho, self.h)
        h *= rho
        x = x_d * g
        y = y_d * g
        xy *= a
        xx *= a
        yy *= a
        x += p1 * xy
        x += p2 * xx
        x += p2 * h
        y += p2 * xy
        y += p1 * yy
        y += p1 * h
        return x, y

    def _finish(
        self,
        x: FloatArray,
        y: FloatArray,
        x_d: FloatArray,
        y_d: FloatArray,
        u: FloatArray,
        v: FloatArray,
        slow: NDArray[np.intp],
    ) -> None:
        """More Newton steps for the indices ``slow``, then the geometry layer's inverse
        for those still short; in place."""
        for _ in range(_EXTRA_STEPS):
            xs, ys = x[slow], y[slow]
            step = _newton_step(xs, ys, x_d[slow], y_d[slow], self.k)
            x[slow] = xs
            y[slow] = ys
            slow = slow[~(step <= _STEP_TOL)]
            if not slow.size:
                return
        # Beyond the fold of the polynomial or not converging: the geometry layer decides.
        x[slow], y[slow] = self.exact(u[slow], v[slow])

    def exact(self, u: FloatArray, v: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Ideal normalised coordinates by the geometry layer's inverse, for the few
        pixels where the fitted start and Newton steps fall short.

        Parameters
        ----------
        u, v : ndarray, shape (N,)
            Pixel coordinates (finite).

        Returns
        -------
        x, y : ndarray, shape (N,)

        Raises
        ------
        ReconstructionError
            When the inverse does not converge or lies beyond the fold of the
            distortion polynomial (no unique ray).
        """
        camera = self.camera
        try:
            exact = camera.normalize(np.stack([u, v], axis=-1))
        except CalibrationError as exc:
            raise ReconstructionError(f"camera {camera.name!r}: {exc}") from None
        _, _, j00, j01, j11 = brown(exact[:, 0], exact[:, 1], camera.dist)
        if not np.all((j00 * j11 - j01 * j01 > 0.0) & (j00 + j11 > 0.0)):
            raise ReconstructionError(
                f"camera {camera.name!r}: pixels beyond the radius where the distortion "
                "polynomial turns back; no unique ray there"
            )
        return exact[:, 0], exact[:, 1]


def normalize_seen(
    lenses: Sequence[Lens], uv: FloatArray, seen: NDArray[np.bool_]
) -> tuple[FloatArray, FloatArray]:
    """Ideal normalised coordinates of the seen observations of C cameras.

    Parameters
    ----------
    lenses : sequence of Lens
        One per camera.
    uv : ndarray, shape (C, N, 2)
        Pixel coordinates.
    seen : ndarray of bool, shape (C, N)
        Observations to undistort; only these are read.

    Returns
    -------
    x, y : ndarray, shape (C, N)
        Ideal normalised coordinates, 0 where unseen.
    """
    x = np.zeros(seen.shape)
    y = np.zeros(seen.shape)
    for c, lens in enumerate(lenses):
        idx = np.flatnonzero(seen[c])
        obs = uv[c].take(idx, axis=0)  # ten times faster than uv[c, idx] for (N, 2)
        x[c, idx], y[c, idx] = lens.normalize(obs[:, 0], obs[:, 1])
    return x, y


def _horner(rho: FloatArray, coef: list[float]) -> FloatArray:
    """``sum_i coef[i] rho^i`` (degree >= 1), lowest power first."""
    out = coef[-1] * rho
    for c in coef[-2:0:-1]:
        out += c
        out *= rho
    out += coef[0]
    return out
