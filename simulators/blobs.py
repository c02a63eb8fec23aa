"""Passive markers rendered as the blobs a video-centroid camera reports.

Per camera and exposure: markers are projected through the camera model
(distortion included); a marker's image is a disc whose diameter follows its
physical size and distance (``f * d / z``); a marker is hidden when it is
behind the camera, outside the image, or a body capsule it is not on crosses
its line of sight. Discs closer than the sum of their radii merge into one
blob (area-weighted centroid of the union, ``merged`` flag). Reflections are
ghost blobs: the floor (z = 0) mirror image of a marker, dimmer, seen by a
fixed, seeded fraction of (camera, marker) pairs. Random noise blobs, and
sunlight (thousands of bright blobs) on demand. Centroids get Gaussian noise;
near (bright) blobs saturate; blobs touching the border are flagged.

Blob kinds in the truth: :data:`KIND_MARKER`, :data:`KIND_MERGED`,
:data:`KIND_GHOST`, :data:`KIND_NOISE`, :data:`KIND_SUN`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from spotlab.geometry import Camera

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]
B = npt.NDArray[np.bool_]

KIND_MARKER, KIND_MERGED, KIND_GHOST, KIND_NOISE, KIND_SUN = 0, 1, 2, 3, 4
SATURATED, EDGE, MERGED = 0x01, 0x02, 0x04
#: Blobs beyond this many in one image are not tested for merges (sunlight).
MERGE_LIMIT = 400
#: Seen marker states in the truth: hidden, own blob, part of a merged blob.
HIDDEN, OWN_BLOB, IN_MERGED = 0, 1, 2


@dataclass(frozen=True)
class BlobModel:
    """How markers become blobs.

    Parameters
    ----------
    marker_diameter_mm : float
        Marker diameter (mm).
    centroid_noise_px : float
        Standard deviation of the centroid noise per coordinate (px).
    ghost_rate : float
        Fraction of (camera, marker) pairs whose floor reflection is a ghost blob.
    ghost_gain : float
        Ghost peak relative to the marker's.
    noise_blobs : float
        Mean random noise blobs per camera and frame (Poisson).
    peak_at_4m : float
        Peak grey level of a marker 4 m away (1/z^2 beyond); above 255 saturates.
    """

    marker_diameter_mm: float = 14.0
    centroid_noise_px: float = 0.07
    ghost_rate: float = 0.02
    ghost_gain: float = 0.35
    noise_blobs: float = 0.02
    peak_at_4m: float = 200.0


@dataclass
class CameraBlobs:
    """One camera's blobs in one exposure, in scan order (top row first).

    Attributes
    ----------
    uv : ndarray, shape (n, 2)
        Centroids (px), noise included.
    area, peak : ndarray, shape (n,)
        Pixels and peak grey level.
    flags : ndarray of uint8, shape (n,)
        ``SATURATED``, ``EDGE``, ``MERGED``.
    marker : ndarray of int64, shape (n,)
        The marker a blob images (the largest member of a merge); -1 for ghosts and noise.
    kind : ndarray of int8, shape (n,)
        ``KIND_*``.
    true_uv : ndarray, shape (n, 2)
        Centroids before noise (px).
    seen : ndarray of int8, shape (M,)
        Per marker: ``HIDDEN``, ``OWN_BLOB`` or ``IN_MERGED``.
    """

    uv: F64
    area: F64
    peak: F64
    flags: npt.NDArray[np.uint8]
    marker: I64
    kind: npt.NDArray[np.int8]
    true_uv: F64
    seen: npt.NDArray[np.int8]


def sight_blocked(centers: F64, X: F64, a: F64, b: F64, radius: F64, on: B) -> B:
    """Lines of sight ``centers[c] -> X[m]`` crossing a capsule the marker is not on.

    Parameters
    ----------
    centers : ndarray, shape (C, 3)
        Camera centres (mm).
    X : ndarray, shape (M, 3)
        Markers (mm).
    a, b, radius : ndarray, shapes (K, 3), (K, 3), (K,)
        Capsule axes and radii (mm).
    on : ndarray of bool, shape (M, K)
        Marker ``m`` is on capsule ``k``.

    Returns
    -------
    ndarray of bool, shape (C, M)

    Notes
    -----
    The closest points of each sight segment and capsule axis are found in closed
    form (clamped to both segments); a capsule counts when it is nearer than its
    radius and lies in front of the marker (not at its very end).
    """
    c0 = centers[:, None, :]
    d1 = X[None, :, :] - c0  # (C, M, 3)
    d2 = b - a  # (K, 3)
    r = c0 - a[None]  # (C, K, 3)
    aa = np.einsum("cmi,cmi->cm", d1, d1)[..., None]  # (C, M, 1)
    ee = np.maximum(np.einsum("ki,ki->k", d2, d2), 1e-9)  # (K,)
    ff = np.einsum("ki,cki->ck", d2, r)[:, None, :]  # (C, 1, K)
    bb = d1 @ d2.T  # (C, M, K)
    cc = np.einsum("cmi,cki->cmk", d1, r)
    denom = aa * ee - bb * bb
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(denom > 1e-9, np.clip((bb * ff - cc * ee) / denom, 0, 1), 0.0)
        t = (bb * s + ff) / ee
        s = np.where(
            t < 0, np.clip(-cc / aa, 0, 1), np.where(t > 1, np.clip((bb - cc) / aa, 0, 1), s)
        )
    t = np.clip(t, 0, 1)
    p1 = c0[:, :, None, :] + s[..., None] * d1[:, :, None, :]
    p2 = a + t[..., None] * d2
    dist = np.linalg.norm(p1 - p2, axis=3)
    length = np.sqrt(aa)
    in_front = s * length < length - radius - 20.0
    return np.asarray(((dist < radius) & in_front & ~on[None]).any(axis=2))


def _project(cam: Camera, X: F64, model: BlobModel) -> tuple[F64, F64, F64, B]:
    """Image centroids (N, 2), diameters (px), raw peaks and whether each is in view."""
    with np.errstate(invalid="ignore"):
        z = X @ cam.R[2] + cam.t[2]
    good = np.isfinite(z) & (z > 100.0)
    zz = np.where(good, z, 1.0)
    uv = cam.project(np.where(good[:, None], X, np.nan))
    w, h = cam.size
    diameter = np.where(good, float(cam.K[0, 0]) * model.marker_diameter_mm / zz, 0.0)
    peak = np.where(good, model.peak_at_4m * (4000.0 / zz) ** 2, 0.0)
    with np.errstate(invalid="ignore"):
        inside = good & (uv >= 0).all(axis=1) & (uv[:, 0] <= w - 1) & (uv[:, 1] <= h - 1)
    return uv, diameter, peak, np.asarray(inside)


def render_camera(
    cam: Camera,
    X: F64,
    model: BlobModel,
    rng: np.random.Generator,
    *,
    capsules: tuple[F64, F64, F64] | None = None,
    on_capsule: B | None = None,
    hidden: B | None = None,
    ghosts: B | None = None,
    sun_blobs: int = 0,
) -> CameraBlobs:
    """The blobs one camera reports for markers at ``X`` (M, 3) mm.

    Parameters
    ----------
    cam : Camera
        The camera.
    X : ndarray, shape (M, 3)
        Marker positions at the exposure mid-point (mm; NaN: absent).
    model : BlobModel
        Sizes, noise, ghosts.
    rng : Generator
        Noise source.
    capsules : (a (K, 3), b (K, 3), radius (K,)), optional
        Body segments that occlude.
    on_capsule : ndarray of bool, shape (M, K), optional
        Marker ``m`` is on capsule ``k`` (not occluded by it).
    hidden : ndarray of bool, shape (M,), optional
        Markers already known to be occluded (:func:`sight_blocked` for several
        cameras at once), instead of ``capsules``.
    ghosts : ndarray of bool, shape (M,), optional
        Markers whose floor reflection this camera sees.
    sun_blobs : int
        Sunlight blobs to add (random, bright).
    """
    m = X.shape[0]
    with_ghosts = ghosts is not None and bool(ghosts.any())
    pts = np.concatenate([X, X[ghosts] * np.array([1.0, 1.0, -1.0])]) if with_ghosts else X
    uv, diam, peak, inside = _project(cam, pts, model)
    marker = np.concatenate([np.arange(m), np.full(pts.shape[0] - m, -1)]).astype(np.int64)
    kind = np.full(pts.shape[0], KIND_GHOST, np.int8)
    kind[:m] = KIND_MARKER
    peak[m:] *= model.ghost_gain
    if capsules is not None and inside[:m].any():
        on = on_capsule if on_capsule is not None else np.zeros((m, capsules[2].size), bool)
        vis = np.flatnonzero(inside[:m])
        inside[vis] &= ~sight_blocked(cam.center[None], X[vis], *capsules, on[vis])[0]
    if hidden is not None:
        inside[:m] &= ~hidden
    seen = np.where(inside[:m], OWN_BLOB, HIDDEN).astype(np.int8)
    n_noise = int(rng.poisson(model.noise_blobs)) if model.noise_blobs > 0 else 0
    if n_noise or sun_blobs:
        w, h = cam.size
        extra = n_noise + sun_blobs
        uv = np.concatenate([uv, rng.uniform([0, 0], [w - 1, h - 1], (extra, 2))])
        diam = np.concatenate([diam, rng.uniform(1.5, 3.0, n_noise), rng.uniform(2, 6, sun_blobs)])
        peak = np.concatenate([peak, np.full(n_noise, 60.0), np.full(sun_blobs, 400.0)])
        marker = np.concatenate([marker, np.full(extra, -1, np.int64)])
        kind = np.concatenate(
            [kind, np.full(n_noise, KIND_NOISE, np.int8), np.full(sun_blobs, KIND_SUN, np.int8)]
        )
        inside = np.concatenate([inside, np.ones(extra, dtype=bool)])
    idx = np.flatnonzero(inside)
    true_uv, d, pk, marker, kind = uv[idx], diam[idx], peak[idx], marker[idx], kind[idx]
    area = np.maximum(np.pi * d * d / 4, 1.0)
    flags = np.zeros(idx.size, dtype=np.uint8)
    if 1 < idx.size <= MERGE_LIMIT:
        true_uv, d, pk, area, marker, kind, flags = _merge(true_uv, d, pk, area, marker, kind, seen)
    return _finish(cam, true_uv, d, pk, area, marker, kind, flags, seen, model, rng)


def _finish(
    cam: Camera, true_uv: F64, d: F64, pk: F64, area: F64, marker: I64,
    kind: npt.NDArray[np.int8], flags: npt.NDArray[np.uint8], seen: npt.NDArray[np.int8],
    model: BlobModel, rng: np.random.Generator,
) -> CameraBlobs:  # fmt: skip
    """Noise, flags and scan order."""
    w, h = cam.size
    r = d / 2
    noisy = np.clip(
        true_uv + rng.normal(0.0, model.centroid_noise_px, true_uv.shape), 0, [w - 1, h - 1]
    )
    edge = (
        (true_uv - r[:, None] < 0).any(axis=1)
        | (true_uv[:, 0] + r > w - 1)
        | (true_uv[:, 1] + r > h - 1)
    )
    flags = (
        flags
        | np.where(edge, EDGE, 0).astype(np.uint8)
        | np.where(pk > 255, SATURATED, 0).astype(np.uint8)
    )
    order = np.lexsort((true_uv[:, 0], true_uv[:, 1] - r))
    return CameraBlobs(
        uv=noisy[order], area=np.rint(area[order]), peak=np.minimum(pk[order], 255.0),
        flags=flags[order], marker=marker[order], kind=kind[order], true_uv=true_uv[order],
        seen=seen,
    )  # fmt: skip


def _merge(
    uv: F64, d: F64, pk: F64, area: F64, marker: I64, kind: npt.NDArray[np.int8],
    seen: npt.NDArray[np.int8],
) -> tuple[F64, F64, F64, F64, I64, npt.NDArray[np.int8], npt.NDArray[np.uint8]]:  # fmt: skip
    """Blobs whose discs overlap become one (area-weighted centroid, merged flag)."""
    n = uv.shape[0]
    du = np.subtract.outer(uv[:, 0], uv[:, 0])
    dv = np.subtract.outer(uv[:, 1], uv[:, 1])
    reach = np.add.outer(d, d)
    touch = 4 * (du * du + dv * dv) < reach * reach  # the diagonal is always true
    flags = np.zeros(n, dtype=np.uint8)
    if np.count_nonzero(touch) == n:
        return uv, d, pk, area, marker, kind, flags
    np.fill_diagonal(touch, False)
    parent = list(range(n))

    def root(k: int) -> int:
        while parent[k] != k:
            k = parent[k]
        return k

    for i, j in zip(*np.nonzero(np.triu(touch)), strict=True):
        parent[root(int(i))] = root(int(j))
    roots = np.array([root(k) for k in range(n)])
    _, label = np.unique(roots, return_inverse=True)
    ncomp = int(label.max()) + 1
    size = np.bincount(label, minlength=ncomp)
    wsum = np.bincount(label, area, ncomp)
    out_uv = np.stack([np.bincount(label, area * uv[:, k], ncomp) / wsum for k in (0, 1)], 1)
    out_area = wsum
    out_d = 2 * np.sqrt(out_area / np.pi)
    out_pk = np.zeros(ncomp)
    np.maximum.at(out_pk, label, pk)
    # The member marker with the largest image names a merged blob.
    out_marker = np.full(ncomp, -1, np.int64)
    best = np.full(ncomp, -1.0)
    for k in np.argsort(area):
        if marker[k] >= 0 and area[k] > best[label[k]]:
            best[label[k]] = area[k]
            out_marker[label[k]] = marker[k]
    out_kind = np.zeros(ncomp, np.int8)
    first = np.full(ncomp, -1)
    first[label[::-1]] = np.arange(n)[::-1]
    out_kind[:] = kind[first]
    merged = size > 1
    out_kind[merged] = KIND_MERGED
    members = marker[(marker >= 0) & merged[label]]
    seen[members] = IN_MERGED
    out_flags = np.where(merged, MERGED, 0).astype(np.uint8)
    return (
        out_uv,
        np.asarray(out_d, np.float64),
        out_pk,
        np.asarray(out_area, np.float64),
        out_marker,
        out_kind,
        out_flags,
    )
