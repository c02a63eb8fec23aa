"""Triangulation of image points seen by several calibrated cameras.

``triangulate(rig, uv)`` returns the 3-D points; ``triangulate_points`` the same with
residuals per ray and per point, the number of views, conditioning and outlier flags.
The estimators (Woltring & Huiskes 1990, Eq. 6-8; Yeadon 1990, Fig. 4) are in
:mod:`spotlab.reconstruction._solvers`; the equations are in ``docs/reconstruction.md``.
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from spotlab.core.errors import ReconstructionError
from spotlab.geometry import Rig
from spotlab.reconstruction import _frame_kernel, _rays, _solvers

__all__ = ["METHODS", "TriangulationResult", "triangulate", "triangulate_points"]

FloatArray = NDArray[np.float64]
Method = Literal["odle", "dlt", "midpoint"]

#: The estimators :func:`triangulate` knows.
METHODS: tuple[str, ...] = ("odle", "dlt", "midpoint")

#: Points per chunk undistorted together (per camera, only the seen observations).
_CHUNK = 1 << 15
#: Rays (cameras x points) per block of the solvers.
_BLOCK_RAYS = 1 << 15
_MIN_BLOCK = 256
#: Largest default number of worker threads.
_MAX_WORKERS = 8


def _workers(workers: int | None, n_blocks: int) -> int:
    """Threads for ``n_blocks`` blocks of work: ``workers`` or the CPUs this process may use."""
    if workers is None:
        workers = min(len(os.sched_getaffinity(0)), _MAX_WORKERS)
    return max(1, min(workers, n_blocks))


@dataclass(frozen=True)
class TriangulationResult:
    """Outcome of :func:`triangulate_points`; ``...`` is the point shape of ``uv``.

    Attributes
    ----------
    points : ndarray, shape (..., 3)
        World points (mm); NaN where fewer than two cameras see a point or its rays are
        (nearly) parallel.
    residuals : ndarray, shape (C, ..., 2)
        Observed minus reprojected pixel coordinates per ray (px), NaN where unseen.
    ray_error : ndarray, shape (C, ..., )
        Length of each ray's residual (px), NaN where unseen.
    rms : ndarray, shape (...)
        Root mean square of a point's ray errors (px).
    n_views : ndarray of int, shape (...)
        Cameras that see each point.
    conditioning : ndarray, shape (...)
        Reciprocal condition number (within a factor of 3) of a point's normal
        equations: about ``theta^2 / 4`` for two rays meeting at angle ``theta``; 0 for
        parallel rays.
    ill_conditioned : ndarray of bool, shape (...)
        Points whose ``conditioning`` is below ``min_conditioning`` (set to NaN).
    outlier : ndarray of bool, shape (...)
        Points with a ray error above ``outlier_px``.
    """

    points: FloatArray
    residuals: FloatArray
    ray_error: FloatArray
    rms: FloatArray
    n_views: NDArray[np.intp]
    conditioning: FloatArray
    ill_conditioned: NDArray[np.bool_]
    outlier: NDArray[np.bool_]


def _seen(uv: FloatArray) -> NDArray[np.bool_]:
    """Observations with both coordinates (a reduction over the last axis of 2 is slow)."""
    return np.isfinite(uv[..., 0]) & np.isfinite(uv[..., 1])


def _check(rig: Any, uv: Any, weights: Any) -> tuple[Rig, FloatArray, FloatArray | None]:
    if not isinstance(rig, Rig):
        raise ReconstructionError(f"rig must be a spotlab Rig, got {type(rig).__name__}")
    try:
        arr = np.asarray(uv, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ReconstructionError(f"uv must be numeric: {exc}") from None
    C = len(rig)
    if arr.ndim < 2 or arr.shape[-1] != 2:
        raise ReconstructionError(f"uv must have shape (C, ..., 2), got {arr.shape}")
    if arr.shape[0] != C:
        raise ReconstructionError(
            f"uv holds observations of {arr.shape[0]} cameras but the rig has {C}"
        )
    if (np.isinf(arr[..., 0]) | np.isinf(arr[..., 1])).any():
        raise ReconstructionError("uv holds infinite values: mark unseen points with NaN")
    if weights is None:
        return rig, arr, None
    else:
        try:
            w = np.broadcast_to(np.asarray(weights, dtype=np.float64), arr.shape[:-1])
        except ValueError:
            raise ReconstructionError(
                f"weights of shape {np.shape(weights)} do not broadcast to the rays "
                f"{arr.shape[:-1]} (C, ...)"
            ) from None
        seen = _seen(arr)
        if not np.all(np.isfinite(w[seen]) & (w[seen] >= 0.0)):
            raise ReconstructionError("weights must be finite and >= 0 for every seen ray")
    return rig, arr, w


def triangulate_points(
    rig: Rig,
    uv: Any,
    method: Method = "odle",
    *,
    weights: Any = None,
    iterations: int | None = None,
    refine: int = 0,
    strict: bool = False,
    min_conditioning: float = 1e-8,
    outlier_px: float = 3.0,
    workers: int | None = 1,
) -> TriangulationResult:
    """Triangulate points and report residuals, views, conditioning and outliers.

    Parameters
    ----------
    rig : Rig
        The calibrated cameras (mm).
    uv : array_like, shape (C, ..., 2)
        Observed (distorted) pixel coordinates per camera: (C, N, 2) for N points, or
        (C, F, M, 2) for F frames of M markers; NaN where a camera does not see a point.
    method : {"odle", "dlt", "midpoint"}
        ``"odle"``: the point nearest to all rays in the weighted least-squares sense
        (Woltring & Huiskes 1990, Eq. 6). ``"dlt"``: least squares on the DLT equations
        (Eq. 7-8) with iterative re-weighting by the projective depth. ``"midpoint"``:
        midpoint of the common perpendicular of two rays (Yeadon 1990); every point
        must be seen by exactly two cameras.
    weights : array_like, shape broadcastable to (C, ...), optional
        Per-ray weights >= 0 (for example inverse variances). For ``"odle"`` the
        default (None) weighs each ray by ``(f / z)^2`` from a first unweighted pass,
        so that ray distances count in pixels; given weights multiply that factor.
        ``weights`` is ignored by ``"midpoint"``.
    iterations : int, optional
        Re-weighting passes after the first solution: ``"odle"`` 1, ``"dlt"`` 2 by
        default. ``iterations=0`` gives the plain Eq. 6 (unweighted ODLE) or Eq. 8 (the
        DLTdv solution).
    refine : int
        Gauss-Newton steps on the reprojection error in distorted pixels after the
        chosen method (0: none). Two steps reach the maximum-likelihood estimate to
        well below the noise.
    strict : bool
        Raise instead of returning NaN for points seen by fewer than two cameras or
        with parallel rays.
    min_conditioning : float
        Points whose normal equations have a reciprocal condition number below this
        (rays closer than about ``2 sqrt(min_conditioning)`` rad to parallel) are
        set to NaN and flagged.
    outlier_px : float
        A point is flagged as an outlier when one of its rays misses it by more than
        this (px).
    workers : int or None
        Threads that share the points, in chunks of up to 32768 points (fewer points:
        one thread); None: as many as the CPUs this process may use (at most 8). The
        threads end before the function returns. The compiled kernel releases the GIL,
        so the threads run in parallel; default 1: on a 2-core machine shared with other
        work a second thread gained only when the other core was free
        (``docs/benchmarks.md``).

    Returns
    -------
    TriangulationResult

    Raises
    ------
    ReconstructionError
        For ``uv`` of the wrong shape, a camera count that differs from the rig's,
        infinite coordinates, invalid weights, an unknown method, ``"midpoint"`` with
        other than two views of a point, pixels where the distortion has no inverse,
        ``workers`` below 1, or (with ``strict``) points that cannot be reconstructed.
    """
    X, uv_flat, shape, extra = _triangulate(
        rig, uv, method, weights, iterations, refine, strict, min_conditioning, workers
    )
    C = len(rig)
    projected = np.stack([cam.project(X) for cam in rig])
    residuals = uv_flat - projected
    ray_error = np.hypot(residuals[..., 0], residuals[..., 1])
    n_views, conditioning, ill = extra
    with np.errstate(invalid="ignore", divide="ignore"):
        rms = np.sqrt(np.nansum(ray_error**2, axis=0) / n_views)
    rms[~np.isfinite(X[:, 0])] = np.nan
    outlier = np.nanmax(np.where(np.isfinite(ray_error), ray_error, -1.0), axis=0) > outlier_px
    return TriangulationResult(
        points=X.reshape(*shape, 3),
        residuals=residuals.reshape(C, *shape, 2),
        ray_error=ray_error.reshape(C, *shape),
        rms=rms.reshape(shape),
        n_views=n_views.reshape(shape),
        conditioning=conditioning.reshape(shape),
        ill_conditioned=ill.reshape(shape),
        outlier=outlier.reshape(shape),
    )


def triangulate(
    rig: Rig,
    uv: Any,
    method: Method = "odle",
    *,
    weights: Any = None,
    iterations: int | None = None,
    refine: int = 0,
    strict: bool = False,
    min_conditioning: float = 1e-8,
    workers: int | None = 1,
) -> FloatArray:
    """World points from their images in several calibrated cameras.

    Parameters
    ----------
    rig, uv, method, weights, iterations, refine, strict, min_conditioning, workers
        As in :func:`triangulate_points`.

    Returns
    -------
    ndarray, shape (..., 3)
        World points (mm); NaN where fewer than two cameras see a point or its rays
        are (nearly) parallel.

    Raises
    ------
    ReconstructionError
        See :func:`triangulate_points`.

    Examples
    --------
    >>> import numpy as np
    >>> from spotlab.reconstruction import triangulate
    >>> from spotlab.simulators.rigs import ring_rig
    >>> rig = ring_rig(4)
    >>> X = np.array([[0.0, 0.0, 1000.0], [250.0, -100.0, 500.0]])
    >>> uv = rig.project(X)
    >>> uv[1:, 1] = np.nan  # the second point is seen by the first camera only
    >>> X = triangulate(rig, uv)
    >>> bool(np.allclose(X[0], [0.0, 0.0, 1000.0], atol=1e-6)), bool(np.isnan(X[1]).all())
    (True, True)
    """
    X, _, shape, _ = _triangulate(
        rig, uv, method, weights, iterations, refine, strict, min_conditioning, workers
    )
    return X.reshape(*shape, 3)


def _triangulate(
    rig: Rig,
    uv: Any,
    method: str,
    weights: Any,
    iterations: int | None,
    refine: int,
    strict: bool,
    min_conditioning: float,
    workers: int | None,
) -> tuple[FloatArray, FloatArray, tuple[int, ...], tuple[Any, FloatArray, Any]]:
    if method not in METHODS:
        raise ReconstructionError(f"unknown triangulation method {method!r}: choose from {METHODS}")
    if iterations is not None and iterations < 0:
        raise ReconstructionError(f"iterations must be >= 0, got {iterations}")
    if refine < 0:
        raise ReconstructionError(f"refine must be >= 0, got {refine}")
    if workers is not None and (
        isinstance(workers, bool) or not isinstance(workers, int | np.integer) or workers < 1
    ):
        raise ReconstructionError(f"workers must be an integer >= 1 or None, got {workers!r}")
    rig, arr, w = _check(rig, uv, weights)
    C = len(rig)
    shape = arr.shape[1:-1]
    flat = np.ascontiguousarray(arr.reshape(C, -1, 2))  # the kernel reads it as is
    seen = _seen(flat)
    n_views = seen.sum(axis=0)
    few = n_views < 2
    if strict and few.any():
        raise ReconstructionError(
            f"{int(few.sum())} of {few.size} points are seen by fewer than two cameras"
        )
    if method == "midpoint":
        many = n_views > 2
        if many.any():
            raise ReconstructionError(
                f"the midpoint method takes exactly two views per point; {int(many.sum())} "
                f"points are seen by up to {int(n_views.max())} cameras (use 'odle' or 'dlt')"
            )
    w_flat = None if w is None else w.reshape(C, -1)
    N = flat.shape[1]
    X = np.empty((N, 3))
    conditioning = np.empty(N)
    origin = np.mean([cam.center for cam in rig], axis=0)
    frame = _solvers.Frame(rig.cameras, origin)
    # The compiled kernel (None: the numpy twin) undistorts, and solves the ODLE, without
    # the GIL: the worker threads then run in parallel.
    kernel = _frame_kernel.load(frame, min_conditioning)
    passes = 1 if iterations is None else iterations
    # Chunks of points whose undistorted coordinates stay in the CPU cache, solved in
    # blocks whose temporaries do too.
    n_workers = _workers(workers, -(-N // _CHUNK))
    n_chunks = max(1, -(-N // _CHUNK))
    n_chunks = -(-n_chunks // n_workers) * n_workers  # the same work for every thread
    step = max(1, -(-N // n_chunks))
    chunks = [slice(start, min(start + step, N)) for start in range(0, N, step)]
    size = max(_MIN_BLOCK, _BLOCK_RAYS // C)

    def run(chunk: slice) -> None:
        solved = kernel is not None and method == "odle"
        with np.errstate(divide="ignore", invalid="ignore"):  # unseen points: masked below
            if kernel is None:
                x, y = _rays.normalize_seen(frame.lenses, flat[:, chunk], seen[:, chunk])
            elif solved:
                w_chunk = None if w_flat is None else w_flat[:, chunk]
                x, y, _ = kernel.odle_range(
                    flat, chunk.start, chunk.stop, w_chunk, passes, X[chunk], conditioning[chunk]
                )
            else:
                x, y, _ = kernel.normalize_range(flat, chunk.start, chunk.stop)
            if solved and not refine:
                return
            for start in range(0, x.shape[1], size):
                b = slice(start, start + size)
                g = slice(chunk.start + start, chunk.start + start + x[:, b].shape[1])
                views = _solvers.Views.build(
                    frame, x[:, b], y[:, b], seen[:, g], None if w_flat is None else w_flat[:, g]
                )
                if solved:  # the kernel's ODLE, refined as _estimate does
                    X[g] = _solvers.refine(views, flat[:, g], X[g], refine)[0]
                else:
                    X[g], conditioning[g] = _estimate(views, flat[:, g], method, iterations, refine)

    if n_workers == 1:
        for chunk in chunks:
            run(chunk)
    else:
        # Threads share the blocks (numpy releases the GIL in its loops); each writes its
        # own rows of X. The pool is joined before returning: no thread outlives the call.
        with ThreadPoolExecutor(n_workers, thread_name_prefix="spotlab-triangulate") as pool:
            for future in [pool.submit(run, chunk) for chunk in chunks]:
                future.result()
    ill = ~few & ~(conditioning >= min_conditioning)
    if strict and ill.any():
        raise ReconstructionError(
            f"{int(ill.sum())} points have (nearly) parallel rays: reciprocal condition "
            f"number below {min_conditioning:g}"
        )
    X[few | ill] = np.nan
    X += origin
    return X, flat, shape, (n_views, conditioning, ill)


def _estimate(
    views: _solvers.Views, flat: FloatArray, method: str, iterations: int | None, refine: int
) -> tuple[FloatArray, FloatArray]:
    """Centred points (N, 3) and their conditioning by the chosen method."""
    if method == "odle":
        X, conditioning = _solvers.odle(views, 1 if iterations is None else iterations, True)
    elif method == "dlt":
        X, conditioning = _solvers.dlt(views, 2 if iterations is None else iterations)
    else:
        X = _solvers.midpoint(views)
        _, conditioning = _solvers.odle(views, 0, False)
    if refine:
        X, _ = _solvers.refine(views, flat, X, refine)
    return X, conditioning
