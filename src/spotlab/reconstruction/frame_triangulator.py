"""Triangulation of one frame at a time, for the live path.

:func:`~spotlab.reconstruction.triangulate` rebuilds per call what depends only on the
rig (the ODLE map, about 0.25 ms for 8 cameras) and undistorts camera by camera: fine
for 100 000 points, most of the time for the 128 markers of one live frame.
:class:`FrameTriangulator` builds the rig's part once and undistorts the observations
of all cameras together, the lens parameters stacked along the camera axis (the same
fitted start and Newton step as :mod:`spotlab.reconstruction._rays`, elementwise the
same arithmetic, so the points equal :func:`triangulate`'s to rounding). The
estimator is the depth-weighted ODLE of :func:`triangulate` (one re-weighting pass).

Where the compiled kernel is built (:mod:`spotlab.reconstruction._frame_kernel`), one
call of it does a frame's work without the GIL; the numpy code here is its twin.
"""

from __future__ import annotations

import copy
from typing import Any

import numpy as np
from numpy.typing import NDArray

from spotlab.core.errors import ReconstructionError
from spotlab.geometry import Rig
from spotlab.reconstruction import _frame_kernel, _rays, _solvers

__all__ = ["FrameTriangulator"]

FloatArray = NDArray[np.float64]


class _LensStack(_rays.Lens):
    """The lenses of C cameras as (C, 1) columns: :meth:`Lens.normalize` on (C, N)."""

    def __init__(self, lenses: list[_rays.Lens]) -> None:  # no super(): stacked columns
        def col(values: list[float]) -> FloatArray:
            return np.array(values, dtype=np.float64)[:, None]

        self.lenses = lenses
        self.cx = col([lens.cx for lens in lenses])  # type: ignore[assignment]
        self.cy = col([lens.cy for lens in lenses])  # type: ignore[assignment]
        self.skew = 0.0  # cameras with skew take the per-camera path
        self.fx_inv = col([lens.fx_inv for lens in lenses])  # type: ignore[assignment]
        self.fy_inv = col([lens.fy_inv for lens in lenses])  # type: ignore[assignment]
        self.k = tuple(col([lens.k[i] for lens in lenses]) for i in range(5))  # type: ignore[misc]
        self.distorted = any(lens.distorted for lens in lenses)
        ng, na, nh = _rays._DEGREES
        # An undistorted lens: start = identity (g = 1, a = h = 0), Newton step 0.
        identity = [1.0] + [0.0] * ng, [0.0] * (na + 1), [0.0] * (nh + 1)

        def coefs(name: str, j: int) -> list[FloatArray]:
            rows = [getattr(lens, name) if lens.distorted else identity[j] for lens in lenses]
            return [col([r[i] for r in rows]) for i in range(len(rows[0]))]

        self.g = coefs("g", 0)  # type: ignore[assignment]
        self.a = coefs("a", 1)  # type: ignore[assignment]
        self.h = coefs("h", 2)  # type: ignore[assignment]

    def widened(self, width: int) -> _LensStack:
        """This stack with every column repeated to shape (C, width): elementwise the
        same arithmetic on (C, width) tables, without the cost of broadcasting (about
        three times that of an operation on equal shapes for a frame's few blobs)."""
        wide = copy.copy(self)

        def rep(col: Any) -> Any:  # a (C, 1) column as a (C, width) table
            return np.repeat(col, width, axis=1)

        wide.cx, wide.cy = rep(self.cx), rep(self.cy)
        wide.fx_inv, wide.fy_inv = rep(self.fx_inv), rep(self.fy_inv)
        wide.k = tuple(rep(c) for c in self.k)
        wide.g = [rep(c) for c in self.g]
        wide.a = [rep(c) for c in self.a]
        wide.h = [rep(c) for c in self.h]
        return wide

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
        """The few slow observations (flat indices into (C, N)), camera by camera."""
        cams, idx = np.unravel_index(slow, x.shape)
        for c in np.unique(cams):
            sel = idx[cams == c]
            self.lenses[c]._finish(x[c], y[c], x_d[c], y_d[c], u[c], v[c], sel)


class FrameTriangulator:
    """Triangulate the markers of one frame of a calibrated rig, with little overhead.

    Parameters
    ----------
    rig : Rig
        The calibrated cameras (mm). Building the triangulator fits (and caches) each
        lens's undistortion start: do it before the first frame arrives.
    min_conditioning : float
        As in :func:`~spotlab.reconstruction.triangulate`: points with (nearly)
        parallel rays are NaN.

    Raises
    ------
    ReconstructionError
        If ``rig`` is not a Rig.

    Examples
    --------
    >>> import numpy as np
    >>> from spotlab.simulators.rigs import ring_rig
    >>> rig = ring_rig(4)
    >>> tri = FrameTriangulator(rig)
    >>> X, rms, views = tri(rig.project(np.array([[10.0, 20.0, 900.0]])))
    >>> bool(np.allclose(X, [[10.0, 20.0, 900.0]], atol=1e-6)), int(views[0])
    (True, 4)
    """

    def __init__(self, rig: Rig, *, min_conditioning: float = 1e-8) -> None:
        if not isinstance(rig, Rig):
            raise ReconstructionError(f"rig must be a spotlab Rig, got {type(rig).__name__}")
        self.rig = rig
        self.min_conditioning = float(min_conditioning)
        self._origin = np.mean([cam.center for cam in rig], axis=0)
        self._frame = _solvers.Frame(rig.cameras, self._origin)
        self._skewed = any(lens.skew for lens in self._frame.lenses)
        self._stack = _LensStack(self._frame.lenses)
        self._R = np.stack([cam.R for cam in rig])
        self._f = np.sqrt(self._frame.f2)  # (C, 1) px
        self._wide: dict[int, _LensStack] = {}  # widened lens stacks by table width
        self._kernel = _frame_kernel.load(self._frame, self.min_conditioning)

    def __call__(self, uv: Any) -> tuple[FloatArray, FloatArray, NDArray[np.intp]]:
        """Points of one frame.

        Parameters
        ----------
        uv : array_like, shape (C, N, 2)
            Distorted pixel coordinates per camera; NaN where a camera does not see a
            marker.

        Returns
        -------
        X : ndarray, shape (N, 3)
            World points (mm); NaN where fewer than two cameras see a marker or its
            rays are (nearly) parallel.
        rms_px : ndarray, shape (N,)
            Root mean square over the seen rays of the distance between each ray and
            the point, in undistorted pixels (principal distance times the normalised
            image error); NaN where ``X`` is.
        n_views : ndarray of int, shape (N,)
            Cameras that see each marker.

        Raises
        ------
        ReconstructionError
            For ``uv`` of the wrong shape, infinite values, or pixels where the
            distortion has no inverse.
        """
        if self._kernel is not None:
            return self._kernel.frame(self._checked(uv))
        x, y, seen = self.normalize(uv)
        everywhere = bool(seen.all())
        X, ray_px, n_views = self._solve(x, y, seen, everywhere)
        ray_px *= ray_px
        if not everywhere:
            ray_px[~seen] = 0.0
        with np.errstate(invalid="ignore", divide="ignore"):  # points seen by no camera
            rms = np.sqrt(ray_px.sum(axis=0) / n_views)
        rms[np.isnan(X[:, 0])] = np.nan
        return X, rms, n_views

    def by_marker(self, uv: Any) -> tuple[FloatArray, FloatArray, NDArray[np.intp]]:
        """Points of one frame given marker by marker (a frame block's layout).

        :meth:`__call__` of ``uv`` with its first two axes swapped; the compiled kernel
        reads this layout as it is, without the transposed copy.

        Parameters
        ----------
        uv : array_like, shape (N, C, 2)
            Distorted pixel coordinates per marker and camera; NaN where unseen.

        Returns
        -------
        X, rms_px, n_views
            As :meth:`__call__`.

        Raises
        ------
        ReconstructionError
            As :meth:`__call__`.
        """
        arr = np.ascontiguousarray(uv, dtype=np.float64)
        C = len(self.rig)
        if arr.ndim != 3 or arr.shape[1] != C or arr.shape[2] != 2:
            raise ReconstructionError(f"uv must have shape (N, {C}, 2), got {arr.shape}")
        if self._kernel is not None:
            return self._kernel.frame(arr, by_marker=True)
        return self(np.swapaxes(arr, 0, 1))

    def normalize(self, uv: Any) -> tuple[FloatArray, FloatArray, NDArray[np.bool_]]:
        """Ideal normalised coordinates of the observations of one frame.

        Parameters
        ----------
        uv : array_like, shape (C, N, 2)
            Distorted pixel coordinates per camera; NaN where unseen.

        Returns
        -------
        x, y : ndarray, shape (C, N)
            Undistorted normalised coordinates; 0 where unseen.
        seen : ndarray of bool, shape (C, N)

        Raises
        ------
        ReconstructionError
            As :meth:`__call__`.
        """
        arr = self._checked(uv)
        if self._kernel is not None:
            return self._kernel.normalize(arr)
        if np.isinf(arr).any():
            raise ReconstructionError("uv holds infinite values: mark unseen points with NaN")
        u, v = arr[..., 0], arr[..., 1]
        seen = np.isfinite(u) & np.isfinite(v)
        if self._skewed:
            x, y = _rays.normalize_seen(self._frame.lenses, arr, seen)
        elif seen.all():  # the usual live frame: no masking
            x, y = self._stack.normalize(u, v)
        else:
            stack = self._stack
            # Unseen observations at the principal point: finite, no Newton trouble.
            u = np.where(seen, u, stack.cx)
            v = np.where(seen, v, stack.cy)
            x, y = stack.normalize(u, v)
            unseen = ~seen
            x[unseen] = 0.0
            y[unseen] = 0.0
        return x, y, seen

    def _checked(self, uv: Any) -> FloatArray:
        """``uv`` as a C-contiguous float64 array of shape (C, N, 2), or raise."""
        arr = np.ascontiguousarray(uv, dtype=np.float64)
        C = len(self.rig)
        if arr.ndim != 3 or arr.shape[0] != C or arr.shape[2] != 2:
            raise ReconstructionError(f"uv must have shape ({C}, N, 2), got {arr.shape}")
        return arr

    def normalize_slots(
        self, uv: FloatArray, camera: NDArray[np.intp], slot: NDArray[np.intp], width: int
    ) -> tuple[FloatArray, FloatArray]:
        """Ideal normalised coordinates of blobs stacked camera by camera.

        The same values as :meth:`normalize` of the (C, width) table holding blob ``i``
        at ``[camera[i], slot[i]]``, computed on a table of a width rounded up to a
        multiple of 16 whose lens columns are built once per width.

        Parameters
        ----------
        uv : ndarray, shape (N, 2)
            Distorted pixels (finite).
        camera, slot : ndarray of int, shape (N,)
            Table places, ``slot < width``.
        width : int

        Returns
        -------
        x, y : ndarray, shape (N,)

        Raises
        ------
        ReconstructionError
            For pixels where the distortion has no inverse.
        """
        C = len(self.rig)
        if self._skewed:
            table = np.full((C, width, 2), np.nan)
            table[camera, slot] = uv
            x, y, _ = self.normalize(table)
            return x[camera, slot], y[camera, slot]
        width = -(-max(width, 1) // 16) * 16
        stack = self._wide.get(width)
        if stack is None:
            if len(self._wide) >= 8:  # a few widths in use; a flooded camera's are not kept
                self._wide.clear()
            stack = self._wide[width] = self._stack.widened(width)
        u = np.array(stack.cx)  # empty places at the principal point, as in normalize
        v = np.array(stack.cy)
        u[camera, slot] = uv[:, 0]
        v[camera, slot] = uv[:, 1]
        x, y = stack.normalize(u, v)
        return x[camera, slot], y[camera, slot]

    def solve(
        self, x: FloatArray, y: FloatArray, seen: NDArray[np.bool_]
    ) -> tuple[FloatArray, FloatArray, NDArray[np.intp]]:
        """Points from undistorted normalised observations (as :meth:`normalize` gives).

        Parameters
        ----------
        x, y : ndarray, shape (C, N)
            Ideal normalised coordinates; any finite value where unseen.
        seen : ndarray of bool, shape (C, N)

        Returns
        -------
        X : ndarray, shape (N, 3)
            World points (mm), NaN as in :meth:`__call__`.
        ray_px : ndarray, shape (C, N)
            Distance between each seen ray and its point in undistorted pixels; NaN
            where unseen or where ``X`` is NaN.
        n_views : ndarray of int, shape (N,)
        """
        if self._kernel is not None:
            return self._kernel.solve(x, y, seen)
        return self._solve(x, y, seen, bool(seen.all()))

    def _solve(
        self, x: FloatArray, y: FloatArray, seen: NDArray[np.bool_], everywhere: bool
    ) -> tuple[FloatArray, FloatArray, NDArray[np.intp]]:
        """:meth:`solve`; ``everywhere``: every observation is seen (no masking)."""
        n_views = seen.sum(axis=0)
        if not everywhere:
            x = np.where(seen, x, 0.0)
            y = np.where(seen, y, 0.0)
        views = _solvers.Views.build(self._frame, x, y, seen, None)
        with np.errstate(divide="ignore", invalid="ignore"):  # unseen points: masked below
            X, conditioning = _solvers.odle(views, 1, True)
            # Ray errors in the centred frame: camera coordinates of X against (x, y, 1).
            Xc = self._R @ X.T  # (C, 3, N); a batched product is 4x faster than einsum here
            Xc += self._frame.t[:, :, None]
            ex = Xc[:, 0] / Xc[:, 2] - x
            ey = Xc[:, 1] / Xc[:, 2] - y
            ray_px = np.sqrt((ex * ex + ey * ey) * self._frame.f2)
        bad = (n_views < 2) | ~(conditioning >= self.min_conditioning)
        if bad.any():
            X[bad] = np.nan
            ray_px[:, bad] = np.nan
        if not everywhere:
            ray_px[~seen] = np.nan
        X += self._origin
        return X, ray_px, n_views
