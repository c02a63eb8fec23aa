"""Linearisation map of a lateral-effect photodiode (PSD) camera from a known target grid.

A PSD reports the centroid of the light on it through the ratio of its electrode currents.
The response is smooth but not linear, worst near the edges of the detector (Woltring
1975). Spots at known detector positions (a target grid seen through the lens, or a
scanned light spot) give measured and true coordinates; a bivariate Chebyshev polynomial
of total degree ``order`` fitted by linear least squares maps measured to true
coordinates, and is applied to every later reading before the camera model.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from numpy.polynomial import chebyshev
from numpy.typing import NDArray

from spotlab.core.errors import CalibrationError

__all__ = ["DetectorLinearisation", "fit_linearisation"]

FloatArray = NDArray[np.float64]

#: Name of the model in :meth:`DetectorLinearisation.to_dict`.
KIND = "chebyshev2d-total-degree"

#: Smallest accepted ratio of the least to the largest singular value of the design matrix.
_RCOND = 1e-10


def _terms(order: int) -> list[tuple[int, int]]:
    """Exponent pairs (i, j) with i + j <= order, the basis T_i(x) T_j(y)."""
    return [(i, d - i) for d in range(order + 1) for i in range(d, -1, -1)]


def _basis(x: FloatArray, y: FloatArray, order: int) -> FloatArray:
    """Design matrix (N, n_terms) of the total-degree Chebyshev basis at scaled points."""
    full = chebyshev.chebvander2d(x, y, [order, order])  # column i * (order+1) + j
    cols = [i * (order + 1) + j for i, j in _terms(order)]
    return np.asarray(full[..., cols])


@dataclass(frozen=True)
class DetectorLinearisation:
    """Smooth 2-D map from measured to true detector coordinates.

    Attributes
    ----------
    order : int
        Total degree of the bivariate Chebyshev polynomial.
    domain : ndarray, shape (2, 2)
        ``[[u_min, u_max], [v_min, v_max]]`` of the measured coordinates of the fit; the
        map is mapped to ``[-1, 1]^2`` over it and is valid only inside it.
    coefficients : ndarray, shape (2, n_terms)
        Coefficients of the true ``u`` and ``v`` per basis term ``T_i(x) T_j(y)``, terms
        ordered by total degree (``(0, 0), (1, 0), (0, 1), (2, 0), (1, 1), (0, 2), ...``).
    residual_rms : float
        ``sqrt(mean |true - map(measured)|^2)`` over the fitting grid (detector units).
    raw_rms : float
        The same figure without correction, ``sqrt(mean |true - measured|^2)``.
    max_residual : float
        Largest residual distance on the fitting grid (detector units).
    n_points : int
        Grid points used for the fit.
    """

    order: int
    domain: FloatArray
    coefficients: FloatArray
    residual_rms: float
    raw_rms: float
    max_residual: float
    n_points: int
    _terms: list[tuple[int, int]] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.order < 1:
            raise CalibrationError(f"order must be >= 1, got {self.order}")
        dom = np.asarray(self.domain, dtype=np.float64)
        if dom.shape != (2, 2) or not np.all(np.isfinite(dom)) or np.any(dom[:, 1] <= dom[:, 0]):
            raise CalibrationError(f"domain must be [[u_min, u_max], [v_min, v_max]], got {dom}")
        terms = _terms(self.order)
        coef = np.asarray(self.coefficients, dtype=np.float64)
        if coef.shape != (2, len(terms)) or not np.all(np.isfinite(coef)):
            raise CalibrationError(
                f"order {self.order} needs finite coefficients of shape (2, {len(terms)}), "
                f"got {coef.shape}"
            )
        object.__setattr__(self, "domain", dom)
        object.__setattr__(self, "coefficients", coef)
        object.__setattr__(self, "_terms", terms)

    def _scaled(self, uv: FloatArray) -> tuple[FloatArray, FloatArray]:
        lo, hi = self.domain[:, 0], self.domain[:, 1]
        xy = (2.0 * uv - (lo + hi)) / (hi - lo)
        return xy[..., 0], xy[..., 1]

    def inside(self, uv: Any) -> NDArray[np.bool_]:
        """Whether each point ``(..., 2)`` lies in the fitted domain; False for NaN."""
        pts = np.asarray(uv, dtype=np.float64)
        lo, hi = self.domain[:, 0], self.domain[:, 1]
        tol = 1e-9 * (hi - lo)
        return np.asarray(np.all((pts >= lo - tol) & (pts <= hi + tol), axis=-1))

    def __call__(
        self, uv: Any, *, outside: Literal["raise", "nan", "extrapolate"] = "raise"
    ) -> FloatArray:
        """Corrected (true) detector coordinates of measured ones.

        Parameters
        ----------
        uv : array_like, shape (..., 2)
            Measured detector coordinates; NaN stays NaN.
        outside : {"raise", "nan", "extrapolate"}
            Points outside the fitted domain: raise :class:`CalibrationError`, return NaN
            for them, or evaluate the polynomial anyway (not recommended: a polynomial
            diverges quickly outside its data).

        Returns
        -------
        ndarray, shape (..., 2)
            Corrected coordinates, same units.
        """
        pts = np.asarray(uv, dtype=np.float64)
        if pts.ndim == 0 or pts.shape[-1] != 2:
            raise CalibrationError(f"uv must have shape (..., 2), got {pts.shape}")
        if outside not in ("raise", "nan", "extrapolate"):
            raise CalibrationError(f"outside must be raise, nan or extrapolate, got {outside!r}")
        finite = np.all(np.isfinite(pts), axis=-1)
        out_of_domain = finite & ~self.inside(pts)
        if outside == "raise" and np.any(out_of_domain):
            first = pts[out_of_domain][0]
            raise CalibrationError(
                f"{int(np.count_nonzero(out_of_domain))} points lie outside the fitted domain "
                f"{self.domain.tolist()} (first: {first.tolist()}): the linearisation is "
                "not valid there"
            )
        x, y = self._scaled(pts)
        corrected = _basis(x, y, self.order) @ self.coefficients.T
        if outside == "nan":
            corrected[out_of_domain] = np.nan
        return np.asarray(corrected)

    def to_dict(self) -> dict[str, Any]:
        """JSON-safe description (plain floats and lists) for a calibration file."""
        return {
            "kind": KIND,
            "order": int(self.order),
            "domain": self.domain.tolist(),
            "terms": [list(t) for t in self._terms],
            "coefficients": self.coefficients.tolist(),
            "residual_rms": float(self.residual_rms),
            "raw_rms": float(self.raw_rms),
            "max_residual": float(self.max_residual),
            "n_points": int(self.n_points),
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> DetectorLinearisation:
        """Rebuild from :meth:`to_dict` output; CalibrationError for anything else."""
        if not isinstance(data, dict) or data.get("kind") != KIND:
            kind = data.get("kind") if isinstance(data, dict) else type(data).__name__
            raise CalibrationError(f"not a detector linearisation of kind {KIND!r}: {kind!r}")
        try:
            order = int(data["order"])
            lin = cls(
                order=order,
                domain=np.asarray(data["domain"], dtype=np.float64),
                coefficients=np.asarray(data["coefficients"], dtype=np.float64),
                residual_rms=float(data["residual_rms"]),
                raw_rms=float(data["raw_rms"]),
                max_residual=float(data["max_residual"]),
                n_points=int(data["n_points"]),
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise CalibrationError(f"detector linearisation entry is incomplete: {exc}") from None
        if "terms" in data and [tuple(t) for t in data["terms"]] != _terms(order):
            raise CalibrationError("detector linearisation terms are not in the expected order")
        return lin


def _check_grid(measured: Any, true: Any) -> tuple[FloatArray, FloatArray]:
    m = np.asarray(measured, dtype=np.float64)
    t = np.asarray(true, dtype=np.float64)
    if m.ndim != 2 or m.shape[1] != 2 or t.shape != m.shape:
        raise CalibrationError(
            f"measured and true must both have shape (N, 2), got {m.shape} and {t.shape}"
        )
    bad = np.flatnonzero(~(np.all(np.isfinite(m), axis=1) & np.all(np.isfinite(t), axis=1)))
    if bad.size:
        raise CalibrationError(
            f"NaN or infinite coordinates at grid points {bad[:10].tolist()}: drop them first"
        )
    sv = np.linalg.svd(m - m.mean(axis=0), compute_uv=False) if m.shape[0] >= 2 else np.zeros(2)
    if not sv[0] > 0.0 or sv[1] < 1e-9 * sv[0]:
        raise CalibrationError(
            "the measured grid points are collinear or coincide: a 2-D map needs a 2-D grid"
        )
    return m, t


def fit_linearisation(
    measured: Any,
    true: Any,
    *,
    order: int = 5,
    domain: Any = None,
) -> DetectorLinearisation:
    """Fit the detector linearisation map from a known target grid.

    Parameters
    ----------
    measured : array_like, shape (N, 2)
        Detector coordinates the camera reports for the grid points (counts or px).
    true : array_like, shape (N, 2)
        Where the grid points really are on the detector, same units.
    order : int
        Total degree of the bivariate polynomial (>= 1); needs
        ``N >= (order + 1) (order + 2) / 2`` points spread over the detector. 5 suits a
        cubic edge non-linearity (see docs/calibration-objects.md for the figures).
    domain : array_like, shape (2, 2), optional
        ``[[u_min, u_max], [v_min, v_max]]`` where the map is valid; by default the
        bounding box of ``measured``. It must hold every measured point.

    Returns
    -------
    DetectorLinearisation
        The map, callable on ``(..., 2)`` arrays, with its residual figures.

    Raises
    ------
    CalibrationError
        NaN or infinite coordinates, mismatched shapes, too few points for the order,
        a collinear grid, a grid that does not determine the polynomial (rank deficient
        design matrix, e.g. too few distinct rows or columns), an invalid domain.

    Notes
    -----
    With ``(x, y)`` the measured coordinates mapped to ``[-1, 1]^2`` over the domain, the
    model is ``true = sum_{i + j <= order} c_ij T_i(x) T_j(y)`` per axis (Chebyshev
    polynomials ``T``). The Chebyshev basis on the scaled square keeps the least-squares
    problem well conditioned (unlike monomials in counts); it is solved by SVD
    (``numpy.linalg.lstsq``) with the columns scaled to unit norm, and rejected when the
    smallest singular value is below 1e-10 of the largest.
    """
    if isinstance(order, bool) or not isinstance(order, (int, np.integer)) or order < 1:
        raise CalibrationError(f"order must be an integer >= 1, got {order!r}")
    order = int(order)
    m, t = _check_grid(measured, true)
    n_terms = len(_terms(order))
    if m.shape[0] < n_terms:
        raise CalibrationError(
            f"too few grid points: order {order} has {n_terms} terms per axis and needs at "
            f"least {n_terms} points, got {m.shape[0]}"
        )
    if domain is None:
        dom = np.column_stack([m.min(axis=0), m.max(axis=0)])
    else:
        dom = np.asarray(domain, dtype=np.float64)
        if dom.shape != (2, 2) or not np.all(np.isfinite(dom)):
            raise CalibrationError(f"domain must be [[u_min, u_max], [v_min, v_max]], got {dom}")
        if np.any(m < dom[:, 0]) or np.any(m > dom[:, 1]):
            raise CalibrationError("domain must hold every measured grid point")
    probe = DetectorLinearisation(order, dom, np.zeros((2, n_terms)), 0.0, 0.0, 0.0, 0)
    A = _basis(*probe._scaled(m), order)
    norms = np.linalg.norm(A, axis=0)
    coef_scaled, _, rank, sv = np.linalg.lstsq(A / norms, t, rcond=None)
    if rank < n_terms or sv[-1] < _RCOND * sv[0]:
        raise CalibrationError(
            f"the grid does not determine an order-{order} map (rank {rank} of {n_terms}, "
            f"condition {sv[-1] / sv[0]:.2g}): use more distinct grid rows and columns, "
            "or a lower order"
        )
    coef = (coef_scaled / norms[:, None]).T
    resid = t - A @ coef.T
    dist = np.hypot(resid[:, 0], resid[:, 1])
    raw = t - m
    return DetectorLinearisation(
        order=order,
        domain=dom,
        coefficients=coef,
        residual_rms=float(np.sqrt(np.mean(dist**2))),
        raw_rms=float(np.sqrt(np.mean(np.sum(raw**2, axis=1)))),
        max_residual=float(dist.max()),
        n_points=int(m.shape[0]),
    )
