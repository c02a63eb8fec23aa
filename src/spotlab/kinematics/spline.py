"""Quintic and cubic smoothing splines: GCVSPL's GCV, Wood & Jennings, fixed p."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from spotlab.kinematics._natural import Spline, natural_spline
from spotlab.kinematics.errors import KinematicsError
from spotlab.kinematics.gcv import FitStatistics, PenalisedSpline, solve_wood_jennings
from spotlab.kinematics.gcv_batch import gcv_fit_many

FloatArray = NDArray[np.float64]


class SmoothingSpline:
    r"""Natural smoothing spline of degree 5 (quintic) or 3 (cubic), like Woltring's GCVSPL.

    Parameters
    ----------
    t : array_like, shape (N,)
        Sample times, s, strictly increasing (need not be equidistant).
    y : array_like, shape (N,) or (N, K)
        Samples; K channels sharing ``t`` are fitted at once, each with its own
        smoothing parameter. NaN marks a missing sample: it gets zero weight,
        so the spline bridges the gap (gap filling).
    sigma : array_like, shape (N,), optional
        Standard error of each sample, in the units of ``y``. When given (and
        ``p`` is not), the smoothing parameter satisfies Wood & Jennings'
        constraint :math:`\sum_i ((g(t_i) - y_i) / \sigma_i)^2 = N`. Without
        it the samples have unit weight and p minimises generalised
        cross-validation (GCVSPL mode 2).
    degree : {5, 3}
        Spline degree 2m - 1: 5 (quintic, m = 3) or 3 (cubic, m = 2).
    p : float, optional
        Fixed smoothing parameter, > 0, in (weight units) s^(2m-1): s^(2m-1)
        with unit weights, s^(2m-1) / y-units^2 with ``sigma``.

    Attributes
    ----------
    p : float or ndarray, shape (K,)
        Smoothing parameter used (GCVSPL's WK(4)).
    gcv : float or ndarray, shape (K,)
        Generalised cross-validation value (WK(1)).
    msr : float or ndarray, shape (K,)
        Mean weighted squared residual (WK(2)).
    dof : float or ndarray, shape (K,)
        Effective degrees of freedom of the fit, trace of the hat matrix.
    residual_dof : float or ndarray, shape (K,)
        ``n - dof`` (WK(3)), n the number of non-missing samples.
    variance : float or ndarray, shape (K,)
        Residual variance estimate ``n msr / (n - dof)`` (WK(6)); with unit
        weights it estimates the noise variance in ``y``-units^2.

    Raises
    ------
    KinematicsError
        Fewer than 2m samples (or non-missing samples), ``t`` not strictly
        increasing or not finite, shapes that disagree, non-positive or
        non-finite ``sigma`` or ``p``, an unsupported degree.

    Notes
    -----
    The spline minimises

    .. math:: \sum_i w_i (y_i - g(t_i))^2 + p \int_{t_1}^{t_N} (g^{(m)}(t))^2 dt,

    with :math:`w_i = 1/\sigma_i^2` (or 1). The minimiser is the natural
    spline of order 2m with knots at the samples (Schoenberg 1964; Reinsch
    1967). Its values f at the samples solve Reinsch's banded system
    :math:`(R + p (m!)^2 Q^T W^{-1} Q)\delta = Q^T y`,
    :math:`f = y - p (m!)^2 W^{-1} Q \delta` (Q^T the m-th divided
    differences, R the Gram matrix of the order-m B-splines of unit integral;
    half-bandwidth m), in O(N) time and memory; the spline is then the natural
    interpolant of f (derivatives m .. 2m - 2 zero at both ends). Missing
    (NaN) samples have zero weight, and a zero-weight sample does not change
    the minimiser, so they are left out of the fit and the spline bridges the
    gap. Near-coincident samples (spacing ~1e-6 of the record) make divided
    differences lose accuracy, as in GCVSPL.
    GCV (Craven & Wahba 1979) is

    .. math:: V(p) = \frac{\frac1n \|W^{1/2}(I - A(p)) y\|^2}{(1 - \operatorname{tr} A(p)/n)^2},

    the trace of the hat matrix A coming from the band of the inverse of the
    banded matrix (Hutchinson & de Hoog 1985), never from a dense matrix.
    Parameterisation and figures are those of GCVSPL (Woltring 1986, Adv Eng
    Software 8:104-113): ``p``, ``msr``, ``residual_dof`` and ``variance``
    agree with its WK(4), WK(2), WK(3), WK(6). Per-sample errors follow Wood
    & Jennings (1979, J Biomech 12:477-479) as used by Yeadon
    (1990). Outside ``[t_1, t_N]`` the spline is its natural extension, a
    polynomial of degree m - 1.
    Channels of ``y`` (N, K) missing the same samples share one banded matrix,
    and their GCV searches run batched (:mod:`spotlab.kinematics.gcv_batch`):
    the results are those of K one-channel calls.

    Examples
    --------
    >>> import numpy as np
    >>> t = np.linspace(0.0, 1.0, 101)
    >>> s = SmoothingSpline(t, t**2, degree=5)
    >>> float(np.round(s(np.array([0.5]), nu=2)[0], 6))
    2.0
    """

    def __init__(
        self,
        t: ArrayLike,
        y: ArrayLike,
        sigma: ArrayLike | None = None,
        degree: int = 5,
        *,
        p: float | None = None,
    ) -> None:
        if degree not in (3, 5):
            raise KinematicsError(f"degree must be 5 (quintic) or 3 (cubic), not {degree}")
        m = (degree + 1) // 2
        tt = np.array(t, dtype=np.float64)
        yy = np.array(y, dtype=np.float64)
        if tt.ndim != 1:
            raise KinematicsError(f"t must be one-dimensional, got shape {tt.shape}")
        self._vector = yy.ndim == 1
        if self._vector:
            yy = yy[:, None]
        if yy.ndim != 2 or yy.shape[0] != tt.size:
            raise KinematicsError(
                f"y must have shape (N,) or (N, K) with N = {tt.size}, got {np.shape(y)}"
            )
        if tt.size < 2 * m:
            raise KinematicsError(
                f"a degree-{degree} spline needs at least {2 * m} samples, got {tt.size}"
            )
        if not np.all(np.isfinite(tt)) or np.any(np.diff(tt) <= 0):
            raise KinematicsError("t must be finite and strictly increasing")
        if sigma is None:
            w = np.ones(tt.size)
        else:
            sig = np.array(sigma, dtype=np.float64)
            if sig.shape != tt.shape or not np.all(np.isfinite(sig)) or np.any(sig <= 0):
                raise KinematicsError(f"sigma must be finite and positive with shape {tt.shape}")
            w = 1.0 / sig**2
        if p is not None and not (np.isfinite(p) and p > 0):
            raise KinematicsError(f"p must be finite and positive, got {p}")
        missing = ~np.isfinite(yy)
        if np.any(missing & ~np.isnan(yy)):
            raise KinematicsError("y holds infinite values; mark missing samples with NaN")
        counts = (~missing).sum(axis=0)
        if np.any(counts < 2 * m):
            raise KinematicsError(
                f"a degree-{degree} spline needs at least {2 * m} non-missing samples per channel"
            )
        self.degree = degree
        self._m = m
        self._t0, self._t1 = float(tt[0]), float(tt[-1])
        k_all = yy.shape[1]
        ps, gcvs, msrs, dofs, variances = (np.zeros(k_all) for _ in range(5))
        self._fits: list[tuple[Spline, NDArray[np.intp]]] = []
        # channels missing the same samples share their knots, weights and banded matrix
        groups: dict[bytes, list[int]] = {}
        for j, key in enumerate(np.packbits(missing, axis=0).T):
            groups.setdefault(key.tobytes(), []).append(j)
        for members in groups.values():
            cols = np.array(members)
            keep = ~missing[:, members[0]]
            # a missing sample has zero weight, and a zero-weight knot does not change the
            # minimiser: fit the samples present, interpolate the gaps with the same spline
            whole = bool(keep.all())  # no copies of long records without gaps
            x = tt if whole else tt[keep]
            problem = PenalisedSpline(x, w if whole else w[keep], m)
            block = yy if whole and len(members) == k_all else yy[keep][:, cols]
            if p is None and sigma is None:
                pg, fitted, stats = gcv_fit_many(problem, block, x=x)
            else:
                pg, fitted, stats = self._fit_given(problem, block, p)
            ps[cols], fitted_cols = pg, fitted
            for j, col in enumerate(cols):
                gcvs[col], msrs[col] = float(stats[j].gcv[0]), float(stats[j].msr[0])
                dofs[col], variances[col] = stats[j].dof, float(stats[j].variance[0])
            del problem  # its bands are as large as the data: not kept while interpolating
            self._fits.append((natural_spline(x, fitted_cols, degree), cols))
        self._k = k_all
        self.p = self._pack(ps)
        self.gcv = self._pack(gcvs)
        self.msr = self._pack(msrs)
        self.dof = self._pack(dofs)
        self.residual_dof = self._pack(counts.astype(np.float64) - dofs)
        self.variance = self._pack(variances)

    @staticmethod
    def _fit_given(
        problem: PenalisedSpline, y: FloatArray, p: float | None
    ) -> tuple[FloatArray, FloatArray, list[FitStatistics]]:
        """Fits at a fixed p (one factor for all channels) or at Wood & Jennings' p each."""
        values = (
            [float(p)]
            if p is not None
            else [solve_wood_jennings(problem, y[:, j : j + 1]) for j in range(y.shape[1])]
        )
        parts = [y] if p is not None else [y[:, j : j + 1] for j in range(y.shape[1])]
        fitted: list[FloatArray] = []
        stats: list[FitStatistics] = []
        for value, part in zip(values, parts, strict=True):
            try:
                fit, st = problem.statistics(value, part)
            except np.linalg.LinAlgError as exc:
                raise KinematicsError(
                    f"p = {value:g} is too large for these {y.shape[0]} samples: the "
                    "banded system is singular to working precision; use a smaller p"
                ) from exc
            fitted.append(fit)
            stats.extend(
                FitStatistics(
                    msr=st.msr[i : i + 1],
                    dof=st.dof,
                    gcv=st.gcv[i : i + 1],
                    variance=st.variance[i : i + 1],
                )
                for i in range(part.shape[1])
            )
        ps = np.full(y.shape[1], values[0]) if p is not None else np.array(values)
        return ps, np.concatenate(fitted, axis=1), stats

    def _pack(self, values: FloatArray) -> float | FloatArray:
        return float(values[0]) if self._vector else np.array(values, dtype=np.float64)

    def __call__(self, t: ArrayLike, nu: int = 0) -> FloatArray:
        """Values or the nu-th derivative of the spline.

        Parameters
        ----------
        t : array_like, shape (M,)
            Times, s.
        nu : int
            Derivative order, 0 .. 3 (units of y per s^nu).

        Returns
        -------
        ndarray, shape (M,) or (M, K)
        """
        if nu not in (0, 1, 2, 3):
            raise KinematicsError(f"nu must be 0, 1, 2 or 3, got {nu}")
        tt = np.asarray(t, dtype=np.float64)
        if not np.all(np.isfinite(tt)):
            raise KinematicsError("evaluation times must be finite")
        out = np.empty((*tt.shape, self._k))
        for fit, cols in self._fits:
            out[..., cols] = self._evaluate(fit, tt, nu)
        return out[..., 0] if self._vector else out

    def _evaluate(self, fit: Spline, t: FloatArray, nu: int) -> FloatArray:
        """Values (..., K_group) of one group's vector-valued spline."""
        out = np.asarray(fit(np.clip(t, self._t0, self._t1), nu=nu), dtype=np.float64)
        # outside [t_1, t_N] the natural spline is the Taylor polynomial of degree m - 1
        for edge, side in ((self._t0, t < self._t0), (self._t1, t > self._t1)):
            if np.any(side):
                dt = (t[side] - edge)[:, None]
                ext = np.zeros((dt.shape[0], out.shape[-1]))
                for order in range(nu, self._m):
                    deriv = np.asarray(fit(edge, nu=order), dtype=np.float64)
                    ext += deriv[None, :] * dt ** (order - nu) / math.factorial(order - nu)
                out[side] = ext
        return out
