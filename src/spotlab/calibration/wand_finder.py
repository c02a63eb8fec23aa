"""A passive wand's markers among a video camera's blobs, frame by frame.

A video-centroid camera reports unidentified blobs: the wand's markers, but also floor
reflections (ghosts), noise, and blobs of two markers merged into one. Per frame and
camera, :func:`find_wand` picks the wand's markers out of them, or drops the image:

- **3 markers** (two ends and a middle marker off the centre, at ``middle_ratio`` of the
  length from end A): every triple of usable blobs is tested. The one between the other
  two is the middle; the triple is the wand when the middle lies on the ends' line
  (within ``COLLINEAR_PX`` + ``COLLINEAR_REL`` of the image length), the image is at
  least ``MIN_LENGTH_PX`` long, and the middle's place along it is ``middle_ratio``
  within ``RATIO_TOLERANCE``. Under perspective the ratio of three collinear points is
  not invariant (a 500 mm wand 2.5 m away pointing into depth moves it by about 0.05),
  hence the tolerance. End A is the end nearer the middle marker, so the ends are the
  same physical ends in every camera. An image is used when exactly one triple passes.
- **2 markers**: an image is used when it holds exactly two usable blobs. Two identical
  markers carry no name; end A is taken as the upper one in the image (cameras stand
  upright and look down at the volume), and images where the wand lies within
  ``LEVEL_DEG`` of the image's horizontal are dropped.

Blobs the camera flagged merged or touching the image edge are not used (their
centroids are biased), nor are cameras flagged offline or overflowing in a frame.
Each image is counted as ``used``, ``ambiguous`` (more than one candidate, or too many
blobs to test), ``missing`` (no candidate: a marker hidden, merged, out of view) or
``unusable`` (camera offline or overflowing).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache
from itertools import combinations

import numpy as np
from numpy.typing import NDArray

from spotlab.core.errors import CalibrationError

__all__ = [
    "COLLINEAR_PX",
    "COLLINEAR_REL",
    "LEVEL_DEG",
    "MAX_BLOBS",
    "MIN_LENGTH_PX",
    "RATIO_TOLERANCE",
    "WandImages",
    "find_wand",
    "middle_places",
]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
IntArray = NDArray[np.int64]

#: Largest distance (px) of the middle marker from the ends' line, plus COLLINEAR_REL of
#: the image length (lens distortion bends the line a little).
COLLINEAR_PX = 1.5
COLLINEAR_REL = 0.02
#: Shortest wand image (px) between the ends: shorter, the ratio says little.
MIN_LENGTH_PX = 20.0
#: Largest difference between the middle marker's place along the image and its place
#: along the wand (fractions of the length).
RATIO_TOLERANCE = 0.07
#: Images with more usable blobs than this are dropped as ambiguous.
MAX_BLOBS = 12
#: Two-marker wand: images whose wand lies within this angle of the horizontal (deg).
LEVEL_DEG = 25.0


@dataclass(frozen=True)
class WandImages:
    """The wand found in every frame and camera.

    Attributes
    ----------
    ends : ndarray, shape (F, C, 2, 2)
        Image points (px) of end A and end B, NaN where the image was not used.
    middle : ndarray, shape (F, C, 2)
        Image point (px) of a 3-marker wand's middle marker, NaN where not used (all
        NaN for a 2-marker wand).
    used, ambiguous, missing, unusable : ndarray of int64, shape (C,)
        Images per camera in each case (see the module docstring); they add up to F.
    ratio_seen : float
        3 markers: the median place of the middle marker along the wand's image, over
        the images of exactly three usable, collinear blobs whatever their ratio (what
        the recording says the wand's ratio is); NaN for 2 markers or no such image.
    """

    ends: FloatArray
    middle: FloatArray
    used: IntArray
    ambiguous: IntArray
    missing: IntArray
    unusable: IntArray
    ratio_seen: float


@cache
def _triples(n: int) -> IntArray:
    """All index triples of ``n`` blobs, shape (K, 3)."""
    return np.array(list(combinations(range(n), 3)), dtype=np.int64).reshape(-1, 3)


def middle_places(
    uv: FloatArray,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """Ends, middle, place and off-line distance of point triples.

    Parameters
    ----------
    uv : ndarray, shape (K, 3, 2)
        Triples of image points (px).

    Returns
    -------
    a, b : ndarray, shape (K, 2)
        The ends, ``a`` the one nearer the middle point.
    m : ndarray, shape (K, 2)
        The middle point: the one not on the triple's longest side.
    place : ndarray, shape (K,)
        Where the middle's foot lies along ``a -> b``, in [0, 0.5] for a middle between
        the ends (fractions of ``|ab|``).
    offline : ndarray, shape (K,)
        Distance of the middle from the line ``ab`` (px); ``|ab|`` is ``length``.
    """
    d = np.stack(
        [
            np.linalg.norm(uv[:, 1] - uv[:, 2], axis=1),  # side opposite point 0
            np.linalg.norm(uv[:, 0] - uv[:, 2], axis=1),
            np.linalg.norm(uv[:, 0] - uv[:, 1], axis=1),
        ],
        axis=1,
    )
    mid = np.argmax(d, axis=1)  # the point opposite the longest side
    rows = np.arange(uv.shape[0])
    others = np.array([[1, 2], [0, 2], [0, 1]])[mid]
    m = uv[rows, mid]
    a, b = uv[rows, others[:, 0]], uv[rows, others[:, 1]]
    ab = b - a
    length2 = np.maximum(np.einsum("ki,ki->k", ab, ab), 1e-12)
    place = np.einsum("ki,ki->k", m - a, ab) / length2
    swap = place > 0.5
    a, b = np.where(swap[:, None], b, a), np.where(swap[:, None], a, b)
    place = np.where(swap, 1.0 - place, place)
    cross = np.abs(ab[:, 0] * (m - a)[:, 1] - ab[:, 1] * (m - a)[:, 0])
    return a, b, m, place, cross / np.sqrt(length2)


def _three(uv: FloatArray, ratio: float) -> tuple[FloatArray | None, int, float]:
    """The wand (A, B, M) (3, 2) among one image's usable blobs, how many triples fit,
    and the middle's place when the image holds exactly one collinear triple (else NaN)."""
    n = uv.shape[0]
    if n < 3:
        return None, 0, np.nan
    idx = _triples(n)
    a, b, m, place, off = middle_places(uv[idx])
    length = np.linalg.norm(b - a, axis=1)
    line = (length >= MIN_LENGTH_PX) & (off <= COLLINEAR_PX + COLLINEAR_REL * length)
    seen = float(place[0]) if n == 3 and line[0] else np.nan
    hits = np.flatnonzero(line & (np.abs(place - ratio) <= RATIO_TOLERANCE))
    if hits.size != 1:
        return None, int(hits.size), seen
    k = int(hits[0])
    return np.stack([a[k], b[k], m[k]]), 1, seen


def _two(uv: FloatArray) -> tuple[FloatArray | None, bool]:
    """The ends (A upper, B) (2, 2) of a 2-marker wand, and whether the image was level."""
    if uv.shape[0] != 2:
        return None, False
    d = uv[1] - uv[0]
    length = float(np.hypot(*d))
    if length < MIN_LENGTH_PX:
        return None, False
    if abs(d[1]) < np.sin(np.radians(LEVEL_DEG)) * length:
        return None, True
    return (uv if d[1] > 0 else uv[::-1]).copy(), False


def find_wand(
    uv: FloatArray,
    offsets: IntArray,
    n_cameras: int,
    *,
    markers: int,
    middle_ratio: float | None = None,
    usable_blob: BoolArray | None = None,
    usable_image: BoolArray | None = None,
) -> WandImages:
    """Find the wand's markers among the blobs of every frame and camera.

    Parameters
    ----------
    uv : ndarray, shape (N, 2)
        Blob centroids (px) of all frames and cameras, flat.
    offsets : ndarray of int, shape (F * C + 1,)
        Blobs of frame ``f`` and camera ``c`` are ``uv[offsets[f*C + c]:offsets[f*C + c + 1]]``.
    n_cameras : int
        ``C``.
    markers : {2, 3}
        Markers on the wand.
    middle_ratio : float, optional
        For 3 markers: the middle marker's distance from end A over the wand's length,
        in (0, 0.5) (the middle marker must be off the centre).
    usable_blob : ndarray of bool, shape (N,), optional
        Blobs that may be wand markers (default: all).
    usable_image : ndarray of bool, shape (F, C), optional
        Images to look at (default: all).

    Returns
    -------
    WandImages

    Raises
    ------
    CalibrationError
        For 2 or 3 markers not given, a middle ratio outside (0, 0.5), or arrays whose
        sizes do not match.
    """
    uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
    offsets = np.asarray(offsets, dtype=np.int64)
    C = int(n_cameras)
    if markers not in (2, 3):
        raise CalibrationError(f"a wand has 2 or 3 markers, not {markers}")
    if markers == 3 and (middle_ratio is None or not 0.0 < middle_ratio < 0.5 - RATIO_TOLERANCE):
        raise CalibrationError(
            "a 3-marker wand's middle marker must sit off the centre: its distance from "
            f"the nearer end over the length must be in (0, {0.5 - RATIO_TOLERANCE:g}), "
            f"got {middle_ratio}"
        )
    if C < 1 or (offsets.size - 1) % C or offsets[-1] != uv.shape[0]:
        raise CalibrationError(
            f"offsets ({offsets.size}) do not fit {C} cameras and {uv.shape[0]} blobs"
        )
    F = (offsets.size - 1) // C
    blob_ok = np.ones(uv.shape[0], bool) if usable_blob is None else np.asarray(usable_blob)
    image_ok = np.ones((F, C), bool) if usable_image is None else np.asarray(usable_image)
    if blob_ok.shape != (uv.shape[0],) or image_ok.shape != (F, C):
        raise CalibrationError("usable_blob must be (N,) and usable_image (F, C)")
    ends = np.full((F, C, 2, 2), np.nan)
    middle = np.full((F, C, 2), np.nan)
    counts = {k: np.zeros(C, np.int64) for k in ("used", "ambiguous", "missing", "unusable")}
    ratio = float(middle_ratio) if middle_ratio is not None else 0.0
    places: list[float] = []
    for f in range(F):
        for c in range(C):
            if not image_ok[f, c]:
                counts["unusable"][c] += 1
                continue
            lo, hi = int(offsets[f * C + c]), int(offsets[f * C + c + 1])
            pts = uv[lo:hi][blob_ok[lo:hi]]
            if pts.shape[0] > MAX_BLOBS:
                counts["ambiguous"][c] += 1
                continue
            if markers == 3:
                found, hits, seen = _three(pts, ratio)
                ambiguous = hits > 1
                if np.isfinite(seen):
                    places.append(seen)
            else:
                found, ambiguous = _two(pts)
                ambiguous = ambiguous or pts.shape[0] > 2
            if found is None:
                counts["ambiguous" if ambiguous else "missing"][c] += 1
                continue
            counts["used"][c] += 1
            ends[f, c] = found[:2]
            if markers == 3:
                middle[f, c] = found[2]
    ratio_seen = float(np.median(places)) if places else np.nan
    return WandImages(ends, middle, **counts, ratio_seen=ratio_seen)
