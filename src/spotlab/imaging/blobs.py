"""Blob centroids of a thresholded frame: the marker detector of a video mocap camera."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from spotlab.imaging._components import label_bright
from spotlab.imaging.errors import ImagingError

__all__ = ["FLAG_EDGE", "FLAG_SATURATED", "FLAG_TOO_MANY", "Blobs", "find_blobs"]

#: A pixel of the blob is at the saturation value: its centroid may be biased.
FLAG_SATURATED = 1
#: The blob touches the image border: part of it may be cut off.
FLAG_EDGE = 2
#: The frame had more blobs than ``max_blobs``: only the brightest were kept. (Bit 2, 4, is
#: left for "merged", as in docs/protocols/centroid.md §4.)
FLAG_TOO_MANY = 8

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]
U8 = npt.NDArray[np.uint8]


@dataclass(frozen=True)
class Blobs:
    """The blobs found in one frame, in raster order of each blob's first pixel.

    Attributes
    ----------
    x, y : ndarray of float64, shape (N,)
        Intensity-weighted centroid (px). Pixel centres are at integer coordinates,
        ``(0, 0)`` the centre of the top-left pixel, ``x`` to the right along a row,
        ``y`` down: the convention of :class:`spotlab.geometry.Camera` (and OpenCV),
        so ``(x, y)`` compare directly with ``Camera.project``.
    area : ndarray of int64, shape (N,)
        Pixels above the threshold (px).
    peak : ndarray of int64, shape (N,)
        Brightest pixel value (image counts).
    flux : ndarray of float64, shape (N,)
        Sum of ``value - threshold`` over the blob (counts): its brightness.
    flags : ndarray of uint8, shape (N,)
        Bits :data:`FLAG_SATURATED`, :data:`FLAG_EDGE`, :data:`FLAG_TOO_MANY`.
    n_components : int
        Connected components above the threshold before the gates.
    truncated : bool
        More blobs passed the gates than ``max_blobs``; the dimmest were dropped.
    flooded : bool
        More than ``max_bright`` of the frame was above the threshold: the frame was
        not searched and no blobs are returned.
    """

    x: F64
    y: F64
    area: I64
    peak: I64
    flux: F64
    flags: U8
    n_components: int
    truncated: bool
    flooded: bool = False

    def __len__(self) -> int:
        return int(self.x.shape[0])

    @property
    def xy(self) -> F64:
        """Centroids as one array, shape (N, 2), columns ``x, y`` (px)."""
        return np.stack([self.x, self.y], axis=1)


def _check(
    image: npt.ArrayLike,
    threshold: float,
    min_area: int,
    max_area: int | None,
    min_peak: float,
    max_blobs: int,
    saturation: int | None,
    max_bright: float,
) -> tuple[npt.NDArray[np.uint8] | npt.NDArray[np.uint16], int]:
    img = np.asarray(image)
    if img.ndim != 2 or 0 in img.shape:
        raise ImagingError(f"image must be a non-empty (H, W) array, got shape {img.shape}")
    if img.dtype not in (np.uint8, np.uint16):
        raise ImagingError(f"image must be uint8 or uint16, got {img.dtype}")
    top = int(np.iinfo(img.dtype).max)
    if not np.isfinite(threshold) or not 0 <= threshold < top:
        raise ImagingError(
            f"threshold must be in [0, {top}) for {img.dtype} images, got {threshold}"
        )
    if min_area < 1:
        raise ImagingError(f"min_area must be at least 1 px, got {min_area}")
    if max_area is not None and max_area < min_area:
        raise ImagingError(f"max_area ({max_area}) is below min_area ({min_area})")
    if not np.isfinite(min_peak):
        raise ImagingError(f"min_peak must be finite, got {min_peak}")
    if max_blobs < 1:
        raise ImagingError(f"max_blobs must be at least 1, got {max_blobs}")
    if not 0 < max_bright <= 1:
        raise ImagingError(f"max_bright must be a share in (0, 1], got {max_bright}")
    sat = top if saturation is None else int(saturation)
    if not threshold < sat <= top:
        raise ImagingError(f"saturation must be in ({threshold}, {top}], got {saturation}")
    return img, sat


def _flooded() -> Blobs:
    none = np.zeros(0)
    ints = np.zeros(0, np.int64)
    return Blobs(none, none, ints, ints, none, np.zeros(0, np.uint8), 0, False, flooded=True)


def find_blobs(
    image: npt.ArrayLike,
    threshold: float,
    *,
    min_area: int = 1,
    max_area: int | None = None,
    min_peak: float = 0.0,
    max_blobs: int = 256,
    saturation: int | None = None,
    max_bright: float = 0.25,
) -> Blobs:
    """Blobs of a frame: threshold, 8-connected components, weighted centroids, gates.

    Parameters
    ----------
    image : array_like of uint8 or uint16, shape (H, W)
        One camera frame (counts).
    threshold : float
        Pixels with a value strictly above it belong to blobs (counts).
    min_area, max_area : int, optional
        Keep blobs of ``min_area <= area <= max_area`` pixels (``None``: no upper bound).
    min_peak : float, optional
        Keep blobs whose brightest pixel is at least this (counts).
    max_blobs : int, optional
        Most blobs returned. Beyond it the brightest (largest ``flux``) are kept and
        every returned blob carries :data:`FLAG_TOO_MANY`: a frame flooded with
        light (sunlight, a reflective surface) stays fast and is flagged.
    saturation : int, optional
        Pixel value that means saturated (default: the dtype's largest value).
    max_bright : float, optional
        Largest share of the frame's pixels above the threshold that is still searched.
        Beyond it the frame is ``flooded`` (light straight into the lens): no blobs,
        found in the time of the threshold alone, instead of labelling half a
        million pixels.

    Returns
    -------
    Blobs
        Centroids (px), areas, peaks, fluxes and flags, in raster order.

    Raises
    ------
    ImagingError
        If the image is not a 2-D uint8/uint16 array, or a threshold or gate is invalid.

    Notes
    -----
    The centroid weights each pixel of the component by ``value - threshold``.
    A pixel's weight thus falls to zero as it crosses the threshold, so the
    centroid moves continuously with the blob instead of jumping when an edge pixel
    enters or leaves; for a blob symmetric about its centre it is unbiased up to the
    pixel sampling. (A plain moment of the thresholded pixels, as in Low-Cost-Mocap,
    has that jump; Low-Cost-Mocap also rounds to integer pixels.) Accuracy on rendered
    discs of 3-10 px: docs/centroiding.md.

    Examples
    --------
    >>> import numpy as np
    >>> img = np.zeros((8, 10), np.uint8)
    >>> img[1:4, 2:5] = [[10, 20, 10], [20, 60, 40], [10, 20, 10]]
    >>> b = find_blobs(img, 5)
    >>> len(b), round(float(b.x[0]), 3), float(b.y[0]), int(b.area[0]), int(b.peak[0])
    (1, 3.129, 2.0, 9, 60)
    """
    img, sat = _check(
        image, threshold, min_area, max_area, min_peak, max_blobs, saturation, max_bright
    )
    height, width = img.shape
    bright = img > threshold
    if np.count_nonzero(bright) > max_bright * bright.size:
        return _flooded()
    index = np.flatnonzero(bright)
    labels, count = label_bright(bright, index)
    values = img.ravel()[index]
    weight = values.astype(np.float64) - float(threshold)
    row, col = np.divmod(index, width)
    area = np.bincount(labels, minlength=count)
    flux: F64 = np.bincount(labels, weights=weight, minlength=count).astype(np.float64)
    x = np.bincount(labels, weights=weight * col, minlength=count)
    y = np.bincount(labels, weights=weight * row, minlength=count)
    peak = np.zeros(count, np.int64)
    np.maximum.at(peak, labels, values.astype(np.int64))
    on_edge = (row == 0) | (row == height - 1) | (col == 0) | (col == width - 1)
    edge = np.bincount(labels, weights=on_edge, minlength=count) > 0

    keep = (area >= min_area) & (peak >= min_peak)
    if max_area is not None:
        keep &= area <= max_area
    kept = np.flatnonzero(keep)
    truncated = kept.shape[0] > max_blobs
    if truncated:
        brightest = np.argsort(-flux[kept], kind="stable")[:max_blobs]
        kept = np.sort(kept[brightest])
    flags = np.zeros(kept.shape[0], np.uint8)
    flags[peak[kept] >= sat] |= FLAG_SATURATED
    flags[edge[kept]] |= FLAG_EDGE
    if truncated:
        flags |= np.uint8(FLAG_TOO_MANY)
    return Blobs(
        x=x[kept] / flux[kept],
        y=y[kept] / flux[kept],
        area=area[kept].astype(np.int64),
        peak=peak[kept],
        flux=flux[kept],
        flags=flags,
        n_components=count,
        truncated=bool(truncated),
    )
