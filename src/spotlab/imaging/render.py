"""Render marker blobs into camera frames, with pixel integration, noise and saturation.

The ground truth of the centroiding tests and benchmark, and the frames of the
fake OAK device. A blob is radially symmetric about its true centre, so its
true centroid is that centre whatever the profile.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
import numpy.typing as npt
import scipy.special

from spotlab.imaging.errors import ImagingError

__all__ = ["render_blobs"]

F64 = npt.NDArray[np.float64]
Profile = Literal["disc", "gaussian"]

#: Blobs rendered together (memory of the oversampled patches stays a few MB).
_CHUNK = 64


def _profile(r: F64, radius: F64, blur: float, kind: Profile) -> F64:
    if kind == "gaussian":
        # radius is half the full width at half maximum
        sigma = radius / np.sqrt(2.0 * np.log(2.0))
        return np.asarray(np.exp(-0.5 * (r / sigma) ** 2))
    if blur <= 0:
        return (r <= radius).astype(np.float64)
    # A disc seen through a Gaussian blur of sigma `blur`: the edge profile of the
    # convolution, exact for radius >> blur and radially symmetric always.
    return np.asarray(0.5 * scipy.special.erfc((r - radius) / (np.sqrt(2.0) * blur)))


def render_blobs(
    size: tuple[int, int],
    centers: npt.ArrayLike,
    diameters: npt.ArrayLike,
    *,
    peak: npt.ArrayLike = 200.0,
    profile: Profile = "disc",
    blur: float = 0.5,
    background: float = 8.0,
    noise: float = 0.0,
    dtype: type[np.uint8] | type[np.uint16] = np.uint8,
    oversample: int = 8,
    rng: np.random.Generator | None = None,
) -> npt.NDArray[np.uint8] | npt.NDArray[np.uint16]:
    """A camera frame with a blob at each centre.

    Parameters
    ----------
    size : (int, int)
        Image ``(width, height)`` (px), as :attr:`spotlab.geometry.Camera.size`.
    centers : array_like, shape (N, 2)
        True blob centres ``(x, y)`` (px), pixel centres at integer coordinates (the
        convention of :func:`spotlab.imaging.find_blobs` and ``Camera.project``).
        Rows with NaN are not drawn.
    diameters : array_like, shape (N,) or scalar
        Disc diameter, or the full width at half maximum for ``"gaussian"`` (px).
    peak : array_like, shape (N,) or scalar, optional
        Brightness of a blob's plateau above the background (counts).
    profile : {"disc", "gaussian"}, optional
        A uniformly lit disc (a retro-reflective marker) blurred by ``blur``, or a
        Gaussian spot.
    blur : float, optional
        Standard deviation of the optics' Gaussian blur for discs (px).
    background : float, optional
        Dark level (counts).
    noise : float, optional
        Standard deviation of additive Gaussian read noise (counts).
    dtype : numpy.uint8 or numpy.uint16, optional
        Pixel type; values are rounded and clipped to its range (saturation).
    oversample : int, optional
        Sub-samples per pixel and axis of the pixel-area integration.
    rng : numpy.random.Generator, optional
        Noise source (default: a fresh unseeded generator).

    Returns
    -------
    ndarray of dtype, shape (height, width)

    Raises
    ------
    ImagingError
        If a size, diameter, brightness or option is invalid.
    """
    width, height = int(size[0]), int(size[1])
    if width < 1 or height < 1:
        raise ImagingError(f"image size must be positive, got {size}")
    xy = np.asarray(centers, dtype=np.float64).reshape(-1, 2)
    n = xy.shape[0]
    diam = np.broadcast_to(np.asarray(diameters, dtype=np.float64), (n,))
    level = np.broadcast_to(np.asarray(peak, dtype=np.float64), (n,))
    if np.any(~np.isfinite(diam) | (diam <= 0)) or np.any(~np.isfinite(level)):
        raise ImagingError("blob diameters must be positive and brightnesses finite")
    if profile not in ("disc", "gaussian") or oversample < 1 or blur < 0 or noise < 0:
        raise ImagingError(
            f"bad rendering options: profile={profile!r}, oversample={oversample}, "
            f"blur={blur}, noise={noise}"
        )
    drawn = np.all(np.isfinite(xy), axis=1)
    xy, diam, level = xy[drawn], diam[drawn], level[drawn]
    canvas = np.full((height, width), float(background))
    if xy.shape[0]:
        reach = diam / 2.0 * (2.0 if profile == "gaussian" else 1.0) + 4.0 * blur + 1.0
        half = int(np.ceil(reach.max()))
        for start in range(0, xy.shape[0], _CHUNK):
            sl = slice(start, start + _CHUNK)
            _add_chunk(canvas, xy[sl], diam[sl] / 2.0, level[sl], half, profile, blur, oversample)
    if noise > 0:
        generator = rng if rng is not None else np.random.default_rng()
        canvas += generator.normal(0.0, noise, canvas.shape)
    top = np.iinfo(dtype).max
    return np.clip(np.rint(canvas), 0, top).astype(dtype)


def _add_chunk(
    canvas: F64,
    xy: F64,
    radius: F64,
    level: F64,
    half: int,
    profile: Profile,
    blur: float,
    oversample: int,
) -> None:
    height, width = canvas.shape
    # Patch of (2 half + 1)^2 pixels around the pixel nearest each centre.
    c0 = np.rint(xy).astype(np.int64) - half
    steps = np.arange(2 * half + 1)
    sub = (np.arange(oversample) + 0.5) / oversample - 0.5
    px = (c0[:, 0, None] + steps)[:, :, None] + sub  # (n, P, k) sub-sample x
    py = (c0[:, 1, None] + steps)[:, :, None] + sub
    dx = px - xy[:, 0, None, None]
    dy = py - xy[:, 1, None, None]
    r = np.sqrt(dy[:, :, :, None, None] ** 2 + dx[:, None, None, :, :] ** 2)  # (n,P,k,P,k)
    shape = _profile(r, radius[:, None, None, None, None], blur, profile)
    pixel = shape.mean(axis=(2, 4)) * level[:, None, None]  # (n, P, P): rows, cols
    rows = c0[:, 1, None] + steps
    cols = c0[:, 0, None] + steps
    for i in range(xy.shape[0]):
        r_ok = (rows[i] >= 0) & (rows[i] < height)
        c_ok = (cols[i] >= 0) & (cols[i] < width)
        if r_ok.any() and c_ok.any():
            canvas[np.ix_(rows[i][r_ok], cols[i][c_ok])] += pixel[i][np.ix_(r_ok, c_ok)]
