"""The compiled kernel of :class:`~spotlab.reconstruction.frame_triangulator.FrameTriangulator`
and of :func:`~spotlab.reconstruction.triangulate`'s undistortion and ODLE.

``_c_frame.c`` does for one frame what the triangulator's numpy path does: the lens's
fitted start and Newton steps for every observation (the same arithmetic in the same
order, so the same bits), the depth-weighted ODLE, the conditioning test, the ray
residuals and their RMS, without the GIL; for ``triangulate`` it undistorts a range of
points and solves the depth-weighted ODLE with per-ray weights and any number of
re-weighting passes, returning the unmasked points and their conditioning. This
module packs the rig into the one buffer the kernel reads (once per rig) and hands the
few observations the Newton steps leave short to the geometry layer, as
:class:`~spotlab.reconstruction._rays.Lens` does. The numpy path stays the twin
(``SPOTLAB_NO_NATIVE=1``, or no C compiler).
"""

from __future__ import annotations

from types import ModuleType

import numpy as np
from numpy.typing import NDArray

from spotlab.core import native
from spotlab.core.errors import ReconstructionError
from spotlab.reconstruction import _rays, _solvers

__all__ = ["FrameKernel", "load"]

FloatArray = NDArray[np.float64]
KERNEL = "spotlab.reconstruction._c_frame"


def load(frame: _solvers.Frame, min_conditioning: float) -> FrameKernel | None:
    """The kernel for a rig, or None when the numpy twin is to run.

    Parameters
    ----------
    frame : Frame
        The rig's cameras, centred (:class:`~spotlab.reconstruction._solvers.Frame`).
    min_conditioning : float

    Returns
    -------
    FrameKernel or None
        None when the kernel was not built or ``SPOTLAB_NO_NATIVE=1``.
    """
    module = native.load(KERNEL)
    return None if module is None else FrameKernel(module, frame, min_conditioning)


def pack(frame: _solvers.Frame, min_conditioning: float) -> FloatArray:
    """The rig as the kernel reads it (layout in the comment at the top of ``_c_frame.c``).

    Parameters
    ----------
    frame : Frame
    min_conditioning : float

    Returns
    -------
    ndarray, shape (8 + C (27 + 7 + 4 + 4),)
    """
    ng, na, nh = (d + 1 for d in _rays._DEGREES)
    C = len(frame.lenses)
    parts = [[float(C), min_conditioning, *frame.origin, ng, na, nh]]
    identity = [1.0] + [0.0] * (ng - 1), [0.0] * na, [0.0] * nh  # unused: not distorted
    for c, lens in enumerate(frame.lenses):
        g, a, h = (lens.g, lens.a, lens.h) if lens.distorted else identity
        intrinsic = [lens.cx, lens.cy, lens.skew, lens.fx_inv, lens.fy_inv, *lens.k]
        R, t = frame.cameras[c].R, frame.t[c]
        pose = [*R.ravel(), *t, float(frame.f2[c, 0]), *(-R.T @ t)]
        parts.append([*intrinsic, float(lens.distorted), *g, *a, *h, *pose])
    return np.array([v for part in parts for v in part], dtype=np.float64)


class FrameKernel:
    """The compiled kernel bound to one rig.

    Parameters
    ----------
    module : module
        ``spotlab.reconstruction._c_frame``.
    frame : Frame
    min_conditioning : float

    Notes
    -----
    Every call allocates its own outputs, so a kernel may serve several threads.
    """

    def __init__(self, module: ModuleType, frame: _solvers.Frame, min_conditioning: float) -> None:
        self._c = module
        self._frame = frame
        self._rig = pack(frame, min_conditioning)
        self._C = len(frame.lenses)

    def frame(
        self, uv: FloatArray, by_marker: bool = False
    ) -> tuple[FloatArray, FloatArray, NDArray[np.intp]]:
        """Points, RMS ray residuals (px) and views of one frame, as
        ``FrameTriangulator.__call__``.

        Parameters
        ----------
        uv : ndarray, shape (C, N, 2), or (N, C, 2) with ``by_marker``
            C-contiguous float64 distorted pixels, NaN where unseen.
        by_marker : bool
            ``uv`` is marker by marker (a frame block's layout).

        Returns
        -------
        X : ndarray, shape (N, 3)
        rms_px : ndarray, shape (N,)
        n_views : ndarray of int, shape (N,)

        Raises
        ------
        ReconstructionError
            For infinite values, or pixels where the distortion has no inverse.
        """
        N = uv.shape[0 if by_marker else 1]
        X = np.empty((N, 3))
        rms = np.empty(N)
        n_views = np.empty(N, dtype=np.int64)
        if self._c.frame(self._rig, N, uv, by_marker, X, rms, n_views) == 0:
            return X, rms, n_views.astype(np.intp, copy=False)
        # Some observations need the geometry layer (or uv holds infinities): step by step.
        x, y, seen = self.normalize(uv, by_marker)
        X, ray_px, n_views = self.solve(x, y, seen)
        ray_px *= ray_px
        ray_px[~seen] = 0.0
        with np.errstate(invalid="ignore", divide="ignore"):
            rms = np.sqrt(ray_px.sum(axis=0) / n_views)
        rms[np.isnan(X[:, 0])] = np.nan
        return X, rms, n_views

    def normalize(
        self, uv: FloatArray, by_marker: bool = False
    ) -> tuple[FloatArray, FloatArray, NDArray[np.bool_]]:
        """``FrameTriangulator.normalize`` of C-contiguous float64 ``uv`` (C, N, 2), or
        (N, C, 2) with ``by_marker``: x, y, seen of shape (C, N)."""
        N = uv.shape[0 if by_marker else 1]
        C = self._C
        x, y = np.empty((C, N)), np.empty((C, N))
        seen, slow = np.empty((C, N), dtype=np.bool_), np.empty(C * N, dtype=np.int64)
        n_slow = self._c.normalize(self._rig, N, uv, by_marker, x, y, seen, slow)
        self._finish(np.swapaxes(uv, 0, 1) if by_marker else uv, x, y, slow, n_slow)
        return x, y, seen

    def solve(
        self, x: FloatArray, y: FloatArray, seen: NDArray[np.bool_]
    ) -> tuple[FloatArray, FloatArray, NDArray[np.intp]]:
        """``FrameTriangulator.solve``: X (N, 3), ray_px (C, N), n_views (N,)."""
        seen = np.ascontiguousarray(seen, dtype=np.bool_)
        N = seen.shape[1]
        X = np.empty((N, 3))
        ray_px = np.empty((self._C, N))
        n_views = np.empty(N, dtype=np.int64)
        self._c.solve(
            self._rig,
            N,
            np.where(seen, np.asarray(x, dtype=np.float64), 0.0),  # unseen rays: 0, as the twin
            np.where(seen, np.asarray(y, dtype=np.float64), 0.0),
            seen,
            X,
            ray_px,
            n_views,
        )
        return X, ray_px, n_views.astype(np.intp, copy=False)

    def normalize_range(
        self, uv: FloatArray, start: int, stop: int
    ) -> tuple[FloatArray, FloatArray, NDArray[np.bool_]]:
        """:func:`spotlab.reconstruction._rays.normalize_seen` of the points
        ``start:stop`` of C-contiguous float64 ``uv`` (C, N, 2), without copying them.

        Returns
        -------
        x, y : ndarray, shape (C, stop - start)
            Ideal normalised coordinates, 0 where unseen (the twin's bits).
        seen : ndarray of bool, shape (C, stop - start)
        """
        x, y, seen, slow = self._scratch(stop - start)
        n_slow = self._c.normalize_range(self._rig, uv.shape[1], uv, start, stop - start, x, y,
                                         seen, slow)  # fmt: skip
        self._finish(uv[:, start:stop], x, y, slow, n_slow)
        return x, y, seen

    def odle_range(
        self,
        uv: FloatArray,
        start: int,
        stop: int,
        weights: FloatArray | None,
        passes: int,
        X: FloatArray,
        conditioning: FloatArray,
    ) -> tuple[FloatArray, FloatArray, NDArray[np.bool_]]:
        """:meth:`normalize_range` and the depth-weighted
        :func:`spotlab.reconstruction._solvers.odle` of the points ``start:stop``, in one
        call where no observation needs the geometry layer.

        Parameters
        ----------
        uv : ndarray, shape (C, N, 2)
            C-contiguous float64 distorted pixels, NaN where unseen.
        start, stop : int
            The points to solve.
        weights : ndarray, shape (C, stop - start), or None
            The caller's per-ray weights (None: 1).
        passes : int
            Re-weighting passes after the first solution (``iterations``).
        X : ndarray, shape (stop - start, 3)
            C-contiguous; gets the centred points, unmasked (the caller masks them).
        conditioning : ndarray, shape (stop - start,)
            C-contiguous; gets the conditioning of the last pass.

        Returns
        -------
        x, y : ndarray, shape (C, stop - start)
        seen : ndarray of bool, shape (C, stop - start)
            As :meth:`normalize_range`.
        """
        n = stop - start
        x, y, seen, slow = self._scratch(n)
        w = None if weights is None else np.ascontiguousarray(weights, dtype=np.float64)
        n_slow = self._c.odle(self._rig, uv.shape[1], uv, start, n, w, passes, X, conditioning,
                              x, y, seen, slow)  # fmt: skip
        if n_slow:  # some observations need the geometry layer (or uv holds infinities)
            self._finish(uv[:, start:stop], x, y, slow, n_slow)
            self._c.odle_solve(self._rig, n, x, y, seen, w, passes, X, conditioning)
        return x, y, seen

    def _scratch(
        self, n: int
    ) -> tuple[FloatArray, FloatArray, NDArray[np.bool_], NDArray[np.int64]]:
        """x, y, seen (C, n) and slow (C n) for one call."""
        C = self._C
        return (
            np.empty((C, n)),
            np.empty((C, n)),
            np.empty((C, n), dtype=np.bool_),
            np.empty(C * n, dtype=np.int64),
        )

    def _finish(
        self, uv: FloatArray, x: FloatArray, y: FloatArray, slow: NDArray[np.int64], n_slow: int
    ) -> None:
        """The geometry layer's inverse for the ``n_slow`` observations the Newton steps
        left short (flat indices in ``slow``), camera by camera; in place."""
        if n_slow < 0:
            raise ReconstructionError("uv holds infinite values: mark unseen points with NaN")
        if n_slow == 0:
            return
        cams, idx = np.unravel_index(slow[:n_slow], x.shape)
        for c in np.unique(cams):
            sel = idx[cams == c]
            obs = uv[c, sel]
            x[c, sel], y[c, sel] = self._frame.lenses[c].exact(obs[:, 0], obs[:, 1])
