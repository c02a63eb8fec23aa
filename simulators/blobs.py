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


def sight_blocked(center: F64, X: F64, a: F64, b: F64, radius: F64, on: B) -> B:
    """Lines of sight ``center -> X`` (M,) crossing a capsule (K,) the marker is not on.

    The closest points of the sight segment and each capsule axis are found in
    closed form (clamped to both segments); a capsule counts when it is nearer
    than its radius and lies in front of the marker (not at its very end).
    """
    d1 = X - center  # (M, 3)
    d2 = b - a  # (K, 3)
    r = center - a  # (K, 3)
    aa = np.einsum("ij,ij->i", d1, d1)[:, None]
    ee = np.maximum(np.einsum("ij,ij->i", d2, d2), 1e-9)[None, :]
    ff = np.einsum("ij,ij->i", d2, r)[None, :]
    bb = d1 @ d2.T
    cc = d1 @ r.T
    denom = aa * ee - bb * bb
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(denom > 1e-9, np.clip((bb * ff - cc * ee) / denom, 0, 1), 0.0)
        t = (bb * s + ff) / ee
        s = np.where(
            t < 0, np.clip(-cc / aa, 0, 1), np.where(t > 1, np.clip((bb - cc) / aa, 0, 1), s)
        )
    t = np.clip(t, 0, 1)
    p1 = center + s[..., None] * d1[:, None, :]
    p2 = a[None] + t[..., None] * d2[None]
    dist = np.linalg.norm(p1 - p2, axis=2)
    length = np.sqrt(aa)
    in_front = s * length < length - radius[None, :] - 20.0
    return np.asarray(((dist < radius[None, :]) & in_front & ~on).any(axis=1))


def _discs(cam: Camera, X: F64, model: BlobModel) -> tuple[F64, F64, F64, B]:
    """Image centroids (M, 2), diameters (px), raw peaks and whether each is in view."""
    with np.errstate(invalid="ignore"):
        z = X @ cam.R[2] + cam.t[2]
        good = np.isfinite(z) & (z > 100.0)
        uv = np.full((X.shape[0], 2), np.nan)
        if good.any():
            uv[good] = cam.project(X[good])
    w, h = cam.size
    f = float(cam.K[0, 0])
    diameter = np.where(good, f * model.marker_diameter_mm / np.where(good, z, 1.0), 0.0)
    peak = np.where(good, model.peak_at_4m * (4000.0 / np.where(good, z, 1.0)) ** 2, 0.0)
    inside = good & (uv[:, 0] >= 0) & (uv[:, 0] <= w - 1) & (uv[:, 1] >= 0) & (uv[:, 1] <= h - 1)
    return uv, diameter, peak, np.asarray(inside)


def render_camera(
    cam: Camera,
    X: F64,
    model: BlobModel,
    rng: np.random.Generator,
    *,
    capsules: tuple[F64, F64, F64] | None = None,
    on_capsule: B | None = None,
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
    ghosts : ndarray of bool, shape (M,), optional
        Markers whose floor reflection this camera sees.
    sun_blobs : int
        Sunlight blobs to add (random, bright).
    """
    m = X.shape[0]
    uv, diam, peak, inside = _discs(cam, X, model)
    if capsules is not None and inside.any():
        on = on_capsule if on_capsule is not None else np.zeros((m, capsules[2].size), bool)
        blocked = np.zeros(m, dtype=bool)
        blocked[inside] = sight_blocked(cam.center, X[inside], *capsules, on[inside])
        inside &= ~blocked
    idx = np.flatnonzero(inside)
    parts_uv, parts_d, parts_pk = [uv[idx]], [diam[idx]], [peak[idx]]
    parts_marker, parts_kind = [idx.astype(np.int64)], [np.full(idx.size, KIND_MARKER, np.int8)]
    if ghosts is not None and ghosts.any():
        mirror = X[ghosts] * np.array([1.0, 1.0, -1.0])
        guv, gd, gpk, gin = _discs(cam, mirror, model)
        parts_uv.append(guv[gin])
        parts_d.append(gd[gin])
        parts_pk.append(gpk[gin] * model.ghost_gain)
        parts_marker.append(np.full(int(gin.sum()), -1, np.int64))
        parts_kind.append(np.full(int(gin.sum()), KIND_GHOST, np.int8))
    w, h = cam.size
    for count, extra_kind, d_lo, d_hi, extra_peak in (
        (
            rng.poisson(model.noise_blobs) if model.noise_blobs > 0 else 0,
            KIND_NOISE,
            1.5,
            3.0,
            60.0,
        ),
        (sun_blobs, KIND_SUN, 2.0, 6.0, 400.0),
    ):
        if count:
            parts_uv.append(rng.uniform([0, 0], [w - 1, h - 1], (count, 2)))
            parts_d.append(rng.uniform(d_lo, d_hi, count))
            parts_pk.append(np.full(count, extra_peak))
            parts_marker.append(np.full(count, -1, np.int64))
            parts_kind.append(np.full(count, extra_kind, np.int8))
    true_uv, d, pk = np.concatenate(parts_uv), np.concatenate(parts_d), np.concatenate(parts_pk)
    marker, kind = np.concatenate(parts_marker), np.concatenate(parts_kind)
    area = np.maximum(np.pi * d * d / 4, 1.0)
    flags = np.zeros(true_uv.shape[0], dtype=np.uint8)
    seen = np.zeros(m, dtype=np.int8)
    seen[idx] = OWN_BLOB
    if 1 < true_uv.shape[0] <= MERGE_LIMIT:
        true_uv, d, pk, area, marker, kind, flags = _merge(true_uv, d, pk, area, marker, kind, seen)
    r = d / 2
    noisy = true_uv + rng.normal(0.0, model.centroid_noise_px, true_uv.shape)
    noisy[:, 0] = np.clip(noisy[:, 0], 0, w - 1)
    noisy[:, 1] = np.clip(noisy[:, 1], 0, h - 1)
    edge = (
        (true_uv - r[:, None] < 0).any(axis=1)
        | (true_uv[:, 0] + r > w - 1)
        | (true_uv[:, 1] + r > h - 1)
    )
    flags |= np.where(edge, EDGE, 0).astype(np.uint8)
    flags |= np.where(pk > 255, SATURATED, 0).astype(np.uint8)
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
    dist = np.linalg.norm(uv[:, None] - uv[None], axis=2)
    touch = dist < (d[:, None] + d[None]) / 2
    np.fill_diagonal(touch, False)
    flags = np.zeros(n, dtype=np.uint8)
    if not touch.any():
        return uv, d, pk, area, marker, kind, flags
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
