"""Blobs of a video-centroid rig watching a walking body, with their true origins.

What each camera of a rig would report for :class:`~spotlab.testing.synthetic_body.WalkingBody`:
centroids with Gaussian noise; markers hidden where they face away from a camera
(self-occlusion), by random occlusion events of one camera or of all; blobs run together
when their spots touch (one blob, flagged merged, at the area-weighted mean); floor
reflections of low markers (mirror images through z = 0: consistent ghost points below
the floor); and random specks. Every blob keeps its origin, so identification can be
scored, and :meth:`SyntheticBlobs.oracle_uv` gives the rays of correctly matched
blobs (the reference 3-D accuracy).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from spotlab.geometry import Rig
from spotlab.reconstruction.identification import BlobFrame
from spotlab.testing.synthetic_body import WalkingBody

__all__ = ["SyntheticBlobs", "synthetic_blobs"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]

#: Marker diameter (mm): spot size in the image is this times f / depth.
MARKER_MM = 14.0


@dataclass(frozen=True)
class SyntheticBlobs:
    """Blob frames with their truth.

    Attributes
    ----------
    time_s : ndarray, shape (F,)
    markers_mm : ndarray, shape (F, M, 3)
        True marker positions.
    labels : tuple of str, length M
    segments : dict of str to tuple of str
        Rigid clusters (segment -> marker labels).
    uv : ndarray, shape (N, 2)
        Blob centroids of all frames (px), frame by frame, camera by camera.
    camera : ndarray of int, shape (N,)
    merged : ndarray of bool, shape (N,)
    source : ndarray of int, shape (N,)
        Marker ``m`` of a blob; ``M + m`` for the floor reflection of marker ``m``;
        -1 for a speck. For a merged blob, one of the markers in it.
    frame_start : ndarray of int, shape (F + 1,)
        Blobs of frame ``f`` are ``frame_start[f]:frame_start[f + 1]``.
    clean_uv : ndarray, shape (C, F, M, 2)
        Centroid of each marker's own unmerged blob, NaN where it has none.
    """

    time_s: FloatArray
    markers_mm: FloatArray
    labels: tuple[str, ...]
    segments: dict[str, tuple[str, ...]]
    uv: FloatArray
    camera: IntArray
    merged: NDArray[np.bool_]
    source: IntArray
    frame_start: IntArray
    clean_uv: FloatArray

    def __len__(self) -> int:
        return int(self.time_s.size)

    def frame(self, f: int) -> BlobFrame:
        """The blobs of frame ``f``."""
        s = slice(int(self.frame_start[f]), int(self.frame_start[f + 1]))
        return BlobFrame(self.uv[s], self.camera[s], self.merged[s])


def _events(
    rng: np.random.Generator, shape: tuple[int, ...], F: int, rate: float, lo: int, hi: int
) -> NDArray[np.bool_]:
    """Random hidden intervals (F, *shape): ``rate`` events per frame, ``lo..hi`` frames long."""
    hidden = np.zeros((F, *shape), dtype=bool)
    n = rng.poisson(rate * F * int(np.prod(shape)))
    starts = rng.integers(0, F, n)
    lengths = rng.integers(lo, hi + 1, n)
    cells = rng.integers(0, int(np.prod(shape)), n)
    flat = hidden.reshape(F, -1)
    for s, length, cell in zip(starts, lengths, cells, strict=True):
        flat[s : s + length, cell] = True
    return hidden


def _merge(
    uv: FloatArray, size: FloatArray, seen: NDArray[np.bool_]
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Pairs ``(f, i, j)`` of spots (F, P) that touch; each spot in one pair at most."""
    upper = np.triu(np.ones((uv.shape[1], uv.shape[1]), dtype=bool), 1)
    found = []
    for start in range(0, uv.shape[0], 256):  # chunks of frames: (n, P, P) arrays fit a cache
        u = np.where(seen[start : start + 256, :, None], uv[start : start + 256], np.inf)
        r = 0.5 * (size[start : start + 256, :, None] + size[start : start + 256, None])
        with np.errstate(invalid="ignore"):  # inf - inf for unseen spots: never touching
            dx = u[:, :, None, 0] - u[:, None, :, 0]
            dy = u[:, :, None, 1] - u[:, None, :, 1]
            touch = (dx * dx + dy * dy < r * r) & upper
        f_c, i_c, j_c = np.nonzero(touch)
        found.append((f_c + start, i_c, j_c))
    f, i, j = (np.concatenate(parts) for parts in zip(*found, strict=True))
    taken: set[tuple[int, int]] = set()
    keep = []
    for k in range(f.size):
        a, b = (int(f[k]), int(i[k])), (int(f[k]), int(j[k]))
        if a not in taken and b not in taken:
            taken.update((a, b))
            keep.append(k)
    sel = np.array(keep, dtype=np.intp)
    return f[sel], np.stack([i[sel], j[sel]], axis=1)


def synthetic_blobs(
    rig: Rig,
    seconds: float = 2.0,
    rate_hz: float = 300.0,
    *,
    seed: int = 0,
    noise_px: float = 0.2,
    occlusion_per_s: float = 0.3,
    full_occlusion_per_s: float = 0.05,
    reflections: bool = True,
    specks_per_frame: float = 0.5,
    body: WalkingBody | None = None,
) -> SyntheticBlobs:
    """Blobs of ``rig`` watching the walking body for ``seconds`` at ``rate_hz``.

    Parameters
    ----------
    rig : Rig
        Cameras (mm).
    seconds, rate_hz : float
        Duration and frame rate.
    seed : int
        Seed of every random draw.
    noise_px : float
        Centroid noise, standard deviation per coordinate (px).
    occlusion_per_s : float
        Rate of occlusion events per marker and camera (each 6-150 frames long).
    full_occlusion_per_s : float
        Rate of events hiding a marker from every camera (each 9-90 frames long).
    reflections : bool
        Floor reflections of markers below 150 mm.
    specks_per_frame : float
        Mean number of random specks per camera and frame.
    body : WalkingBody, optional

    Returns
    -------
    SyntheticBlobs
    """
    rng = np.random.default_rng(np.random.SeedSequence([seed, 0xB10B]))
    body = body or WalkingBody()
    F = round(seconds * rate_hz)
    t = np.arange(F) / rate_hz
    X = body.markers(t)
    normal = body.outward(t)
    M = X.shape[1]
    C = len(rig)
    full = _events(rng, (M,), F, full_occlusion_per_s / rate_hz, 9, 90)
    mirror = X * np.array([1.0, 1.0, -1.0])
    low = X[..., 2] < 150.0 if reflections else np.zeros((F, M), dtype=bool)
    P = np.concatenate([X, mirror], axis=1)  # (F, 2M, 3): markers, then reflections
    rows: list[tuple[NDArray[Any], ...]] = []
    clean = np.full((C, F, M, 2), np.nan)
    for c, cam in enumerate(rig):
        uv = cam.project(P)
        to_cam = cam.center - X
        depth = np.linalg.norm(to_cam, axis=-1)
        facing = np.einsum("fmi,fmi->fm", normal, to_cam) / depth > -0.25
        hidden = _events(rng, (M,), F, occlusion_per_s / rate_hz, 6, 150) | full
        w, h = cam.size
        inside = (uv[..., 0] >= 1) & (uv[..., 0] <= w - 2) & (uv[..., 1] >= 1)
        inside &= uv[..., 1] <= h - 2
        seen = inside & np.concatenate([facing & ~hidden, facing & ~hidden & low], axis=1)
        size = MARKER_MM * cam.K[0, 0] / np.concatenate([depth, depth], axis=1)
        fm, pairs = _merge(uv, size, seen)
        uv = uv + rng.normal(0.0, noise_px, uv.shape)
        merged = np.zeros((F, 2 * M), dtype=bool)
        area = size**2
        a, b = pairs[:, 0], pairs[:, 1]
        wa, wb = area[fm, a], area[fm, b]
        uv[fm, a] = (wa[:, None] * uv[fm, a] + wb[:, None] * uv[fm, b]) / (wa + wb)[:, None]
        merged[fm, a] = True
        seen[fm, b] = False
        own = seen[:, :M] & ~merged[:, :M]
        clean[c][own] = uv[:, :M][own]
        f_idx, p_idx = np.nonzero(seen)
        rows.append((f_idx, np.full(f_idx.size, c), uv[f_idx, p_idx], merged[f_idx, p_idx], p_idx))
        n_specks = rng.poisson(specks_per_frame, F)
        f_sp = np.repeat(np.arange(F), n_specks)
        xy = rng.uniform([0, 0], [w - 1, h - 1], (f_sp.size, 2))
        rows.append(
            (f_sp, np.full(f_sp.size, c), xy, np.zeros(f_sp.size, bool), np.full(f_sp.size, -1))
        )
    frame = np.concatenate([r[0] for r in rows])
    cams = np.concatenate([r[1] for r in rows])
    order = np.lexsort((cams, frame))
    return SyntheticBlobs(
        time_s=t,
        markers_mm=X,
        labels=body.labels,
        segments=body.segments,
        uv=np.concatenate([r[2] for r in rows])[order],
        camera=cams[order].astype(np.intp),
        merged=np.concatenate([r[3] for r in rows])[order],
        source=np.concatenate([r[4] for r in rows])[order].astype(np.intp),
        frame_start=np.searchsorted(frame[order], np.arange(F + 1)).astype(np.intp),
        clean_uv=clean,
    )
