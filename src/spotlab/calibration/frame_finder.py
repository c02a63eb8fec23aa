"""A static reference object's markers (an L-frame) among a video camera's blobs.

The object stands still through a short recording, so per camera:

1. **Static blobs.** Blobs that come back at the same place (within ``STATIC_RADIUS_PX``)
   in at least ``STATIC_SHARE`` of the usable images are the object's (or a static
   reflection); their centroids are averaged over every image in which they appear.
   Noise blobs and anything that moves are left out.
2. **Which is which.** Every assignment of the object's P markers to the static blobs is
   tested against the object's own geometry, with invariants of a perspective view:
   a triple of markers on one line must be on one line in the image (within
   ``COLLINEAR_PX`` + ``COLLINEAR_REL`` of its length) with the middle marker between the
   others at its place along the line (within ``RATIO_TOLERANCE``; perspective moves it a
   little); a triple off a line must stay off it; and for a flat object, seen from the
   side its normal points up to (world +z: cameras look down at the floor), the image
   keeps the object's handedness. The camera's markers are found when exactly one
   assignment passes, or (with the blobs' peaks given) one of several is clearly the
   brightest (its dimmest blob ``BRIGHTER`` times brighter than the dimmest of every
   other: floor reflections are dimmer); otherwise the camera is counted ``ambiguous`` (several) or
   ``not found`` (none: a marker hidden, or fewer static blobs than markers).

The L-frame of spotlab's simulator (markers at (0, 0), (200, 0), (600, 0), (0, 400) mm)
is told apart by its x arm: three collinear markers with the middle one a third of the
way out. An object with no three markers on a line can only be told apart by its
handedness and is usually ambiguous.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache
from itertools import combinations, permutations

import numpy as np
from numpy.typing import NDArray

from spotlab.calibration.wand_finder import BRIGHTER, COLLINEAR_PX, COLLINEAR_REL, checked_blobs
from spotlab.core.errors import CalibrationError

__all__ = [
    "FOUND",
    "MAX_STATIC_BLOBS",
    "RATIO_TOLERANCE",
    "STATIC_RADIUS_PX",
    "STATIC_SHARE",
    "FrameImages",
    "find_frame",
]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
IntArray = NDArray[np.int64]

#: A static blob's centroids stay within this radius (px).
STATIC_RADIUS_PX = 3.0
#: A static blob appears in at least this share of the usable images.
STATIC_SHARE = 0.5
#: Place of a middle marker along its line, tolerance (fractions of the line's length).
RATIO_TOLERANCE = 0.1
#: Cameras with more static blobs than this are counted ambiguous.
MAX_STATIC_BLOBS = 9
#: Images sampled to find the static blobs.
_SAMPLE_IMAGES = 60
#: Collinearity of the object's own markers (mm).
_LINE_MM = 1.0
FOUND, AMBIGUOUS, NOT_FOUND = "found", "ambiguous", "not found"


@dataclass(frozen=True)
class FrameImages:
    """The reference object's markers found in each camera of a static recording.

    Attributes
    ----------
    uv : ndarray, shape (C, P, 2)
        Mean image point (px) of each marker, NaN where the camera's markers were not
        found.
    spread_px : ndarray, shape (C, P)
        Standard deviation of each marker's centroid over the images (px, per axis,
        the larger), NaN where not found.
    images : ndarray of int64, shape (C,)
        Usable images per camera.
    static_blobs : ndarray of int64, shape (C,)
        Static blobs per camera.
    status : list of str
        Per camera: ``found``, ``ambiguous`` or ``not found``.
    fits : ndarray of int64, shape (C,)
        Assignments that passed every test.
    """

    uv: FloatArray
    spread_px: FloatArray
    images: IntArray
    static_blobs: IntArray
    status: list[str]
    fits: IntArray


@dataclass(frozen=True)
class _Geometry:
    """Tests derived from the object's marker coordinates."""

    lines: IntArray  # (L, 3): end nearer the middle, far end, middle
    places: FloatArray  # (L,)
    open_: IntArray  # (T, 3): triples off a line
    hand: FloatArray  # (T,): +-1 image orientation of each open triple, 0 if not flat


def _geometry(points: FloatArray) -> _Geometry:
    P = points.shape[0]
    lines, places, open_ = [], [], []
    for tri in combinations(range(P), 3):
        p = points[list(tri)]
        d = [np.linalg.norm(p[(k + 1) % 3] - p[(k + 2) % 3]) for k in range(3)]
        mid = int(np.argmax(d))
        e1, e2 = [k for k in range(3) if k != mid]
        a, b, m = p[e1], p[e2], p[mid]
        ab = b - a
        place = float(np.dot(m - a, ab) / np.dot(ab, ab))
        off = float(np.linalg.norm(np.cross(ab, m - a)) / np.linalg.norm(ab))
        if off > _LINE_MM:
            open_.append(tri)
            continue
        if place > 0.5:
            e1, e2, place = e2, e1, 1.0 - place
        lines.append((tri[e1], tri[e2], tri[mid]))
        places.append(place)
    centred = points - points.mean(axis=0)
    _, s, vt = np.linalg.svd(centred)
    flat = s.size == 3 and s[2] <= 1e-3 * s[0]
    normal = vt[2] if vt[2][2] >= 0 else -vt[2]
    hand = []
    for i, j, k in open_:
        turn = float(np.dot(np.cross(points[j] - points[i], points[k] - points[i]), normal))
        hand.append(-np.sign(turn) if flat and abs(normal[2]) > 0.5 else 0.0)  # image y down
    return _Geometry(
        np.array(lines, np.int64).reshape(-1, 3),
        np.array(places, np.float64),
        np.array(open_, np.int64).reshape(-1, 3),
        np.array(hand, np.float64),
    )


@cache
def _assignments(n: int, P: int) -> IntArray:
    """Every ordered choice of P of n blobs, shape (K, P)."""
    return np.array(list(permutations(range(n), P)), dtype=np.int64).reshape(-1, P)


def _cross(u: FloatArray, v: FloatArray) -> FloatArray:
    return np.asarray(u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0])


def _fits(blobs: FloatArray, geo: _Geometry, P: int) -> IntArray:
    """Assignments (K, P) of the object's markers to ``blobs`` (n, 2) that pass every test."""
    cand = _assignments(blobs.shape[0], P)
    ok = np.ones(cand.shape[0], dtype=bool)
    for (e1, e2, mid), place in zip(geo.lines, geo.places, strict=True):
        a, b, m = blobs[cand[:, e1]], blobs[cand[:, e2]], blobs[cand[:, mid]]
        ab = b - a
        length = np.linalg.norm(ab, axis=1)
        t = np.einsum("ki,ki->k", m - a, ab) / np.maximum(length**2, 1e-12)
        off = np.abs(_cross(ab, m - a)) / np.maximum(length, 1e-12)
        ok &= (off <= COLLINEAR_PX + COLLINEAR_REL * length) & (
            np.abs(t - place) <= RATIO_TOLERANCE
        )
    for (i, j, k), hand in zip(geo.open_, geo.hand, strict=True):
        a, b, c = blobs[cand[:, i]], blobs[cand[:, j]], blobs[cand[:, k]]
        turn = _cross(b - a, c - a)
        longest = np.maximum.reduce(
            [
                np.linalg.norm(b - a, axis=1),
                np.linalg.norm(c - a, axis=1),
                np.linalg.norm(c - b, axis=1),
            ]
        )
        height = np.abs(turn) / np.maximum(longest, 1e-12)
        ok &= height > 2.0 * (COLLINEAR_PX + COLLINEAR_REL * longest)
        if hand != 0.0:
            ok &= np.sign(turn) == hand
    return cand[ok]


def _static_blobs(
    images: list[FloatArray], peaks: list[FloatArray]
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Centres (K, 2), spreads (K,) and mean peaks (K,) of the blobs that stay put in
    most images."""
    n = len(images)
    pick = np.unique(np.linspace(0, n - 1, min(n, _SAMPLE_IMAGES)).astype(int))
    seeds = np.concatenate([images[i] for i in pick]) if pick.size else np.zeros((0, 2))
    owner = np.concatenate([np.full(images[i].shape[0], k) for k, i in enumerate(pick)])
    if seeds.shape[0] == 0:
        return np.zeros((0, 2)), np.zeros(0), np.zeros(0)
    near = np.linalg.norm(seeds[:, None] - seeds[None], axis=2) <= STATIC_RADIUS_PX
    onehot = np.zeros((seeds.shape[0], pick.size), dtype=bool)
    onehot[np.arange(seeds.shape[0]), owner] = True
    support = (near.astype(np.int64) @ onehot.astype(np.int64) > 0).sum(axis=1)
    free = np.ones(seeds.shape[0], dtype=bool)
    centres = []
    for i in np.argsort(-support, kind="stable"):
        if support[i] < STATIC_SHARE * pick.size:
            break
        if not free[i]:
            continue
        members = near[i] & free
        centres.append(seeds[members].mean(axis=0))
        free &= ~near[i]
    if not centres:
        return np.zeros((0, 2)), np.zeros(0), np.zeros(0)
    centre = np.array(centres)
    allpts = np.concatenate(images)
    allpeaks = np.concatenate(peaks)
    dist = np.linalg.norm(allpts[:, None] - centre[None], axis=2)  # (N, K)
    near_all = dist <= STATIC_RADIUS_PX
    K = centre.shape[0]
    n_near = np.maximum(near_all.sum(axis=0), 1)
    mean = np.stack([allpts[near_all[:, k]].sum(axis=0) / n_near[k] for k in range(K)])
    spread = np.array(
        [allpts[near_all[:, k]].std(axis=0).max() if n_near[k] > 1 else 0.0 for k in range(K)]
    )
    bright = np.array([allpeaks[near_all[:, k]].mean() if n_near[k] else 0.0 for k in range(K)])
    return mean, spread, bright


def find_frame(
    uv: FloatArray,
    offsets: IntArray,
    n_cameras: int,
    points: FloatArray,
    *,
    usable_blob: BoolArray | None = None,
    usable_image: BoolArray | None = None,
    peak: FloatArray | None = None,
) -> FrameImages:
    """Find the reference object's markers in every camera of a static recording.

    Parameters
    ----------
    uv : ndarray, shape (N, 2)
        Blob centroids (px) of all frames and cameras, flat.
    offsets : ndarray of int, shape (F * C + 1,)
        Blobs of frame ``f`` and camera ``c`` are ``uv[offsets[f*C + c]:offsets[f*C + c + 1]]``.
    n_cameras : int
        ``C``.
    points : ndarray, shape (P, 3)
        The object's marker coordinates (mm), 3 <= P <= 8.
    usable_blob : ndarray of bool, shape (N,), optional
        Blobs that may be markers (default: all).
    usable_image : ndarray of bool, shape (F, C), optional
        Images to look at (default: all).
    peak : ndarray, shape (N,), optional
        The blobs' peak grey levels (of several fitting assignments the clearly brightest
        is taken; without them the camera is ambiguous).

    Returns
    -------
    FrameImages

    Raises
    ------
    CalibrationError
        For a number of markers outside 3-8, or arrays whose sizes do not match.
    """
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3 or not 3 <= points.shape[0] <= 8:
        raise CalibrationError(
            f"the reference object needs 3 to 8 markers (P, 3), got {points.shape}"
        )
    uv, offsets, C, _, blob_ok, image_ok = checked_blobs(
        uv, offsets, n_cameras, usable_blob, usable_image
    )
    P = points.shape[0]
    geo = _geometry(points)
    out = np.full((C, P, 2), np.nan)
    spread = np.full((C, P), np.nan)
    images = np.zeros(C, np.int64)
    n_static = np.zeros(C, np.int64)
    fits = np.zeros(C, np.int64)
    status = []
    pk = np.ones(uv.shape[0]) if peak is None else np.asarray(peak, np.float64).reshape(-1)
    if pk.shape != (uv.shape[0],):
        raise CalibrationError(f"peak must have one value per blob ({uv.shape[0]},)")
    for c in range(C):
        per_image, per_peak = [], []
        for f in np.flatnonzero(image_ok[:, c]):
            lo, hi = int(offsets[f * C + c]), int(offsets[f * C + c + 1])
            per_image.append(uv[lo:hi][blob_ok[lo:hi]])
            per_peak.append(pk[lo:hi][blob_ok[lo:hi]])
        images[c] = len(per_image)
        centre, sd, bright = _static_blobs(per_image, per_peak)
        n_static[c] = centre.shape[0]
        if centre.shape[0] < P:
            status.append(NOT_FOUND)
            continue
        if centre.shape[0] > MAX_STATIC_BLOBS:
            status.append(AMBIGUOUS)
            continue
        ok = _fits(centre, geo, P)
        fits[c] = ok.shape[0]
        if ok.shape[0] > 1 and peak is not None:
            dimmest = bright[ok].min(axis=1)
            ranked = np.sort(dimmest)
            if ranked[-1] >= BRIGHTER * ranked[-2]:
                ok = ok[[int(np.argmax(dimmest))]]
        if ok.shape[0] != 1:
            status.append(AMBIGUOUS if ok.shape[0] else NOT_FOUND)
            continue
        out[c] = centre[ok[0]]
        spread[c] = sd[ok[0]]
        status.append(FOUND)
    return FrameImages(out, spread, images, n_static, status, fits)
