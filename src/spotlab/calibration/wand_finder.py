"""A passive wand's markers among a video camera's blobs, frame by frame.

A video-centroid camera reports unidentified blobs: the wand's markers, but also floor
reflections (ghosts), noise, and blobs of two markers merged into one. Per frame and
camera, :func:`find_wand` picks the wand's markers out of them, or drops the image:

- **3 markers** (two ends and a middle marker off the centre, at ``middle_ratio`` of the
  length from end A): every triple of usable blobs is tested. The one between the other
  two is the middle; the triple is the wand when the middle lies on the ends' line
  (within ``COLLINEAR_PX`` plus ``COLLINEAR_REL`` of the image length), the image is at
  least ``MIN_LENGTH_PX`` long, and the middle's place along it is ``middle_ratio``
  within ``RATIO_TOLERANCE``. Under perspective the ratio of three collinear points is
  not invariant (a 500 mm wand 2.5 m away pointing into depth moves it by about 0.05),
  hence the tolerance. End A is the end nearer the middle marker, so the ends are the
  same physical ends in every camera. An image is used when exactly one triple passes,
  or (with the blobs' peaks given) when one of several is clearly the brightest: its
  dimmest blob ``BRIGHTER`` times brighter than the dimmest of every other (a floor
  reflection of the whole wand is a second wand, dimmer).
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
    "BRIGHTER",
    "COLLINEAR_PX",
    "COLLINEAR_REL",
    "LEVEL_DEG",
    "MAX_BLOBS",
    "MIN_LENGTH_PX",
    "RATIO_TOLERANCE",
    "WandImages",
    "WandSurvey",
    "checked_blobs",
    "find_wand",
    "middle_places",
    "survey_wand",
]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
IntArray = NDArray[np.int64]

#: Largest distance (px) of the middle marker from the ends' line, plus COLLINEAR_REL of
#: the image length (lens distortion bends the line a little).
COLLINEAR_PX = 1.5
COLLINEAR_REL = 0.005
#: Shortest wand image (px) between the ends: shorter, the ratio says little.
MIN_LENGTH_PX = 20.0
#: Largest difference between the middle marker's place along the image and its place
#: along the wand (fractions of the length).
RATIO_TOLERANCE = 0.07
#: Images with more usable blobs than this are dropped as ambiguous.
MAX_BLOBS = 12
#: Of several fitting triples, one whose dimmest blob is this many times brighter than
#: every other's is the wand.
BRIGHTER = 1.5
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
    """

    ends: FloatArray
    middle: FloatArray
    used: IntArray
    ambiguous: IntArray
    missing: IntArray
    unusable: IntArray


@dataclass(frozen=True)
class WandSurvey:
    """What a wand recording's images say about the wand, before looking for it.

    Attributes
    ----------
    two : int
        Images of exactly two usable blobs at least ``MIN_LENGTH_PX`` apart.
    three_in_line : int
        Images of exactly three usable blobs on one line (collinearity as for the wand).
    ratio_seen : float
        Median place of the middle blob along the line in those images (from the nearer
        end, fractions of the image length; NaN when there is none): the wand's middle
        ratio as the recording shows it, give or take perspective.
    """

    two: int
    three_in_line: int
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


def _in_line(a: FloatArray, b: FloatArray, off: FloatArray) -> BoolArray:
    """Triples whose middle is on the ends' line and whose image is long enough."""
    length = np.linalg.norm(b - a, axis=1)
    return np.asarray((length >= MIN_LENGTH_PX) & (off <= COLLINEAR_PX + COLLINEAR_REL * length))


def _three(uv: FloatArray, ratio: float, peak: FloatArray | None) -> tuple[FloatArray | None, int]:
    """The wand (A, B, M) (3, 2) among one image's usable blobs, and how many triples fit."""
    n = uv.shape[0]
    if n < 3:
        return None, 0
    idx = _triples(n)
    a, b, m, place, off = middle_places(uv[idx])
    hits = np.flatnonzero(_in_line(a, b, off) & (np.abs(place - ratio) <= RATIO_TOLERANCE))
    if hits.size > 1 and peak is not None:
        dimmest = np.sort(peak[idx[hits]].min(axis=1))
        if dimmest[-1] >= BRIGHTER * dimmest[-2]:
            hits = hits[[int(np.argmax(peak[idx[hits]].min(axis=1)))]]
    if hits.size != 1:
        return None, int(hits.size)
    k = int(hits[0])
    return np.stack([a[k], b[k], m[k]]), 1


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
    peak: FloatArray | None = None,
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
    peak : ndarray, shape (N,), optional
        The blobs' peak grey levels: of several fitting triples the clearly brightest is
        taken (see the module docstring); without them such an image is ambiguous.

    Returns
    -------
    WandImages

    Raises
    ------
    CalibrationError
        For 2 or 3 markers not given, a middle ratio outside (0, 0.5), or arrays whose
        sizes do not match.
    """
    if markers not in (2, 3):
        raise CalibrationError(f"a wand has 2 or 3 markers, not {markers}")
    if markers == 3 and (middle_ratio is None or not 0.0 < middle_ratio < 0.5 - RATIO_TOLERANCE):
        raise CalibrationError(
            "a 3-marker wand's middle marker must sit off the centre: its distance from "
            f"the nearer end over the length must be in (0, {0.5 - RATIO_TOLERANCE:g}), "
            f"got {middle_ratio}"
        )
    uv, offsets, C, F, blob_ok, image_ok = checked_blobs(
        uv, offsets, n_cameras, usable_blob, usable_image
    )
    pk = None if peak is None else np.asarray(peak, dtype=np.float64).reshape(-1)
    if pk is not None and pk.shape != (uv.shape[0],):
        raise CalibrationError(f"peak must have one value per blob ({uv.shape[0]},)")
    ends = np.full((F, C, 2, 2), np.nan)
    middle = np.full((F, C, 2), np.nan)
    counts = {k: np.zeros(C, np.int64) for k in ("used", "ambiguous", "missing", "unusable")}
    ratio = float(middle_ratio) if middle_ratio is not None else 0.0
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
                found, hits = _three(pts, ratio, None if pk is None else pk[lo:hi][blob_ok[lo:hi]])
                ambiguous = hits > 1
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
    return WandImages(ends, middle, **counts)


def checked_blobs(
    uv: FloatArray, offsets: IntArray, n_cameras: int, usable_blob: BoolArray | None,
    usable_image: BoolArray | None,
) -> tuple[FloatArray, IntArray, int, int, BoolArray, BoolArray]:  # fmt: skip
    """Arrays as float/int, C, F and the two masks (all true when not given)."""
    uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
    offsets = np.asarray(offsets, dtype=np.int64)
    C = int(n_cameras)
    if C < 1 or (offsets.size - 1) % C or offsets[-1] != uv.shape[0]:
        raise CalibrationError(
            f"offsets ({offsets.size}) do not fit {C} cameras and {uv.shape[0]} blobs"
        )
    F = (offsets.size - 1) // C
    blob_ok = np.ones(uv.shape[0], bool) if usable_blob is None else np.asarray(usable_blob)
    image_ok = np.ones((F, C), bool) if usable_image is None else np.asarray(usable_image)
    if blob_ok.shape != (uv.shape[0],) or image_ok.shape != (F, C):
        raise CalibrationError("usable_blob must be (N,) and usable_image (F, C)")
    return uv, offsets, C, F, blob_ok, image_ok


def survey_wand(
    uv: FloatArray,
    offsets: IntArray,
    n_cameras: int,
    *,
    usable_blob: BoolArray | None = None,
    usable_image: BoolArray | None = None,
) -> WandSurvey:
    """Count the images that look like a 2-marker and like a 3-marker wand.

    Parameters are those of :func:`find_wand`.

    Returns
    -------
    WandSurvey
    """
    uv, offsets, C, _, blob_ok, image_ok = checked_blobs(
        uv, offsets, n_cameras, usable_blob, usable_image
    )
    two = 0
    triples = []
    for f, c in zip(*np.nonzero(image_ok), strict=True):
        lo, hi = int(offsets[f * C + c]), int(offsets[f * C + c + 1])
        pts = uv[lo:hi][blob_ok[lo:hi]]
        if pts.shape[0] == 2 and np.hypot(*(pts[1] - pts[0])) >= MIN_LENGTH_PX:
            two += 1
        elif pts.shape[0] == 3:
            triples.append(pts)
    if not triples:
        return WandSurvey(two, 0, np.nan)
    a, b, _, place, off = middle_places(np.stack(triples))
    line = _in_line(a, b, off)
    seen = float(np.median(place[line])) if line.any() else np.nan
    return WandSurvey(two, int(line.sum()), seen)
