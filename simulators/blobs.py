"""Passive markers rendered as the blobs a video-centroid camera reports.

Per camera and exposure: markers are projected through the camera model
(distortion included); a marker's image is a disc whose diameter follows its
physical size and distance (``f * d / z``); a marker is hidden when it is
behind the camera, outside the image, or a body capsule it is not on crosses
its line of sight. Discs closer than the sum of their radii merge into one
blob (area-weighted centroid of the union); the hub flags a blob ``merged`` from its
measured shape (elongation), so nearly coincident markers pass as one round blob and
a small single blob is now and then flagged, as on real hardware. Reflections are
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
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from spotlab.geometry import Camera
from spotlab.simulators.blob_optics import Optics, project_many

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
    merge_elongation : float
        The hub flags a blob merged when its measured elongation (ratio of its
        principal axes) exceeds this.
    shape_noise : float
        Noise of the measured elongation times the blob's diameter (px): the
        elongation of a ``d``-pixel blob is measured up to ``|N(0, 1)| shape_noise / d``
        too long.
    """

    marker_diameter_mm: float = 14.0
    centroid_noise_px: float = 0.07
    ghost_rate: float = 0.02
    ghost_gain: float = 0.35
    noise_blobs: float = 0.02
    peak_at_4m: float = 200.0
    merge_elongation: float = 1.3
    shape_noise: float = 0.3


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


def _unit(x: F64) -> F64:
    """``x`` clipped to [0, 1] (NaN stays NaN)."""
    return np.minimum(np.maximum(x, 0.0), 1.0)


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
    # d1 . r (C, M, K), summed in the order numpy's einsum sums three terms.
    t0, t1, t2 = (d1[:, :, None, i] * r[:, None, :, i] for i in range(3))
    cc = (t0 + t2) + t1
    denom = aa * ee - bb * bb
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(denom > 1e-9, _unit((bb * ff - cc * ee) / denom), 0.0)
        t = (bb * s + ff) / ee
        s = np.where(t < 0, _unit(-cc / aa), np.where(t > 1, _unit((bb - cc) / aa), s))
    t = _unit(t)
    # |p1 - p2| coordinate by coordinate on (C, M, K) arrays, p1 = c0 + s d1, p2 = a + t d2
    # (the sums in the order of a norm over the last axis: the same bits).
    dx, dy, dz = (
        (c0[:, :, None, i] + s * d1[:, :, None, i]) - (a[:, i] + t * d2[:, i]) for i in range(3)
    )
    dist = np.sqrt((dx * dx + dy * dy) + dz * dz)
    length = np.sqrt(aa)
    in_front = s * length < length - radius - 20.0
    return np.asarray(((dist < radius) & in_front & ~on[None]).any(axis=2))


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
    blocked = np.zeros(m, dtype=bool) if hidden is None else np.asarray(hidden, dtype=bool)
    if capsules is not None:
        on = on_capsule if on_capsule is not None else np.zeros((m, capsules[2].size), bool)
        with np.errstate(invalid="ignore"):
            blocked = blocked | sight_blocked(cam.center[None], X, *capsules, on)[0]
    return render_cameras(
        [cam], X[None], model, rng, hidden=blocked[None],
        ghosts=None if ghosts is None else np.asarray(ghosts, dtype=bool)[None],
        sun_blobs=[sun_blobs],
    )[0]  # fmt: skip


def render_cameras(
    cams: list[Camera],
    X: F64,
    model: BlobModel,
    rng: np.random.Generator,
    *,
    hidden: B | None = None,
    ghosts: B | None = None,
    sun_blobs: list[int] | None = None,
    optics: Optics | None = None,
) -> list[CameraBlobs]:
    """The blobs of ``n`` cameras in one frame, rendered together.

    Parameters
    ----------
    cams : list of Camera, length n
        The cameras.
    X : ndarray, shape (n, M, 3)
        Marker positions at each camera's exposure mid-point (mm; NaN: absent).
    model : BlobModel
        Sizes, noise, ghosts.
    rng : Generator
        Noise source.
    hidden : ndarray of bool, shape (n, M), optional
        Markers occluded from each camera (:func:`sight_blocked`).
    ghosts : ndarray of bool, shape (n, M), optional
        Markers whose floor reflection each camera sees.
    sun_blobs : list of int, length n, optional
        Sunlight blobs to add per camera (random, bright).
    optics : Optics, optional
        ``cams`` stacked (:meth:`Optics.of`), when the caller keeps them between frames.

    Returns
    -------
    list of CameraBlobs, length n
        Each camera's blobs as :func:`render_camera` describes them.
    """
    n, m = X.shape[0], X.shape[1]
    if ghosts is not None and ghosts.any():
        mirror = X * np.array([1.0, 1.0, -1.0])
        P = np.concatenate([X, np.where(ghosts[..., None], mirror, np.nan)], axis=1)
    else:
        P = X
    optics = Optics.of(cams) if optics is None else optics
    uv, diam, peak, inside = project_many(optics, P, model.marker_diameter_mm, model.peak_at_4m)
    peak[:, m:] *= model.ghost_gain
    if hidden is not None:
        inside[:, :m] &= ~hidden
    seen = np.where(inside[:, :m], OWN_BLOB, HIDDEN).astype(np.int8)  # (n, M)
    cam_of, point = np.nonzero(inside)  # camera-major: blobs grouped by camera
    cam_of = cam_of.astype(np.int64)
    marker = np.where(point < m, point, -1).astype(np.int64)
    kind = np.where(point < m, KIND_MARKER, KIND_GHOST).astype(np.int8)
    true_uv, d, pk = uv[cam_of, point], diam[cam_of, point], peak[cam_of, point]
    sun = np.zeros(n, np.int64) if sun_blobs is None else np.asarray(sun_blobs, np.int64)
    n_noise = np.asarray(
        rng.poisson(model.noise_blobs, n) if model.noise_blobs > 0 else np.zeros(n), np.int64
    )
    if n_noise.any() or sun.any():
        size = optics.size - 1  # (n, 2)
        ec = np.concatenate([np.repeat(np.arange(n), n_noise), np.repeat(np.arange(n), sun)])
        k_noise = int(n_noise.sum())
        e_uv = rng.uniform(0.0, 1.0, (ec.size, 2)) * size[ec]
        e_d = np.concatenate([rng.uniform(1.5, 3.0, k_noise), rng.uniform(2, 6, ec.size - k_noise)])
        is_noise = np.arange(ec.size) < k_noise
        order = np.argsort(np.concatenate([cam_of, ec]), kind="stable")
        cam_of = np.concatenate([cam_of, ec])[order]
        true_uv = np.concatenate([true_uv, e_uv])[order]
        d = np.concatenate([d, e_d])[order]
        pk = np.concatenate([pk, np.where(is_noise, 60.0, 400.0)])[order]
        marker = np.concatenate([marker, np.full(ec.size, -1, np.int64)])[order]
        e_kind = np.where(is_noise, KIND_NOISE, KIND_SUN).astype(np.int8)
        kind = np.concatenate([kind, e_kind])[order]
    area = np.maximum(np.pi * d * d / 4, 1.0)
    cols = _merge_many(n, cam_of, true_uv, d, pk, area, marker, kind, seen)
    return _finish_many(optics.size, *cols, seen, model, rng)


#: camera, centroid (px), diameter (px), peak, area (px), marker, kind, elongation
_Cols = tuple[I64, F64, F64, F64, F64, I64, npt.NDArray[np.int8], F64]


def _merge_many(
    n: int, cam_of: I64, uv: F64, d: F64, pk: F64, area: F64, marker: I64,
    kind: npt.NDArray[np.int8], seen: npt.NDArray[np.int8],
) -> _Cols:  # fmt: skip
    """Blobs whose discs overlap become one (area-weighted centroid).

    A blob's elongation is the square root of the ratio of the principal second
    moments of its shape: 1 for a disc; for two equal discs ``s`` apart,
    ``sqrt(1 + (2 s / d)^2)``.

    Discs are tested pairwise within each camera (one padded test for all cameras);
    the blobs that touch, directly or through others, form one blob. Images with more
    than :data:`MERGE_LIMIT` blobs (sunlight) are not tested. The member marker with
    the largest image names a merged blob; ``seen`` marks its members ``IN_MERGED``.
    """
    counts = np.bincount(cam_of, minlength=n)
    todo = np.flatnonzero((counts > 1) & (counts <= MERGE_LIMIT))
    cols: _Cols = (cam_of, uv, d, pk, area, marker, kind, np.ones(cam_of.size))
    if todo.size == 0:
        return cols
    tested = np.zeros(n, dtype=bool)
    tested[todo] = True
    a, b = _touching(cam_of, uv, d, tested)
    if a.size == 0:
        return cols
    N = cam_of.size
    ncomp, label = _components(N, a, b)
    size = np.bincount(label, minlength=ncomp)
    wsum = np.bincount(label, area, ncomp)
    out_uv = np.stack([np.bincount(label, area * uv[:, k], ncomp) / wsum for k in (0, 1)], 1)
    out_pk = np.zeros(ncomp)
    np.maximum.at(out_pk, label, pk)
    first = np.full(ncomp, -1)
    first[label[::-1]] = np.arange(N)[::-1]
    out_marker = np.full(ncomp, -1, np.int64)
    named = np.flatnonzero(marker >= 0)
    by_area = named[np.lexsort((area[named], label[named]))]  # largest last per component
    out_marker[label[by_area]] = marker[by_area]
    merged = size > 1
    out_kind = np.where(merged, KIND_MERGED, kind[first]).astype(np.int8)
    members = (marker >= 0) & merged[label]
    seen[cam_of[members], marker[members]] = IN_MERGED
    # Second moments of each union of discs (a disc of radius r: r^2 / 4 per axis).
    du, dv = (uv - out_uv[label]).T
    r2 = d * d / 16.0
    mxx = np.bincount(label, area * (r2 + du * du), ncomp) / wsum
    myy = np.bincount(label, area * (r2 + dv * dv), ncomp) / wsum
    mxy = np.bincount(label, area * du * dv, ncomp) / wsum
    half = np.hypot(0.5 * (mxx - myy), mxy)
    mid = 0.5 * (mxx + myy)
    elong = np.sqrt((mid + half) / np.maximum(mid - half, 1e-12))
    out_d = np.asarray(2 * np.sqrt(wsum / np.pi), np.float64)
    head = (cam_of[first], out_uv, out_d, out_pk, np.asarray(wsum, np.float64), out_marker)
    return (*head, out_kind, np.asarray(elong, np.float64))


def _touching(cam_of: I64, uv: F64, d: F64, tested: B) -> tuple[I64, I64]:
    """Pairs of blobs of one camera whose discs overlap: ``4 |uv_a - uv_b|^2 < (d_a + d_b)^2``.

    Parameters
    ----------
    cam_of : ndarray of int64, shape (N,)
        Camera of each blob.
    uv, d : ndarray, shapes (N, 2), (N,)
        Centres and diameters (px).
    tested : ndarray of bool, shape (n,)
        Cameras whose blobs are tested.

    Returns
    -------
    a, b : ndarray of int64, shape (P,)
        The pairs (blob indices), each once.

    Notes
    -----
    Blobs sorted by camera, then ``v``: only those within a diameter below a blob (in
    ``v``, same camera) can overlap it; the overlap test itself is exact on them.
    """
    sel = np.flatnonzero(tested[cam_of])
    none = np.zeros(0, np.int64)
    if sel.size < 2:
        return none, none
    key = cam_of[sel] * _CAMERA_KEY + uv[sel, 1]
    rank = np.argsort(key, kind="stable")
    order, key = sel[rank], key[rank]
    bound = 1.01 * float(d[sel].max()) + 1e-3  # > half of any reach: those never overlap
    m = order.size
    count = np.searchsorted(key, key + bound, side="right") - np.arange(1, m + 1)
    total = int(count.sum())
    if total == 0:
        return none, none
    first = np.repeat(np.arange(m), count)
    second = first + 1 + np.arange(total) - np.repeat(np.cumsum(count) - count, count)
    x, y = order[first], order[second]
    du, dv = uv[x, 0] - uv[y, 0], uv[x, 1] - uv[y, 1]
    reach = d[x] + d[y]
    hit = 4 * (du * du + dv * dv) < reach * reach
    return x[hit], y[hit]


#: Camera spacing of the sort key of :func:`_touching` (px, far beyond any image).
_CAMERA_KEY = 1 << 20


#: Above this many touching pairs the components are found by scipy's graph search.
_FEW_PAIRS = 64


def _components(n: int, a: I64, b: I64) -> tuple[int, I64]:
    """Connected components of ``n`` nodes joined by the edges ``a[i] - b[i]``.

    Returns
    -------
    ncomp : int
        Number of components.
    label : ndarray of int64, shape (n,)
        Component of each node; components are numbered in the order of their
        lowest node, as :func:`scipy.sparse.csgraph.connected_components` numbers them.

    Notes
    -----
    A frame has a handful of touching pairs among hundreds of blobs: joining them
    one by one (union-find, the lower node the root) costs far less than building
    a sparse graph; many pairs (noise, crowded images) go to scipy.
    """
    if a.size > _FEW_PAIRS:
        graph = coo_matrix((np.ones(a.size), (a, b)), shape=(n, n))
        ncomp, lab = connected_components(graph, directed=False)
        return int(ncomp), np.asarray(lab, np.int64)
    parent: dict[int, int] = {}

    def root(x: int) -> int:
        while x in parent:
            x = parent[x]
        return x

    for u, v in zip(a.tolist(), b.tolist(), strict=True):
        ru, rv = root(u), root(v)
        if ru != rv:
            parent[max(ru, rv)] = min(ru, rv)
    top = np.arange(n)
    if parent:
        nodes = list(parent)
        top[nodes] = [root(x) for x in nodes]
    rank = np.cumsum(top == np.arange(n)) - 1
    return int(rank[-1]) + 1, rank[top]


def _finish_many(
    image_size: F64, cam_of: I64, true_uv: F64, d: F64, pk: F64, area: F64, marker: I64,
    kind: npt.NDArray[np.int8], elong: F64, seen: npt.NDArray[np.int8],
    model: BlobModel, rng: np.random.Generator,
) -> list[CameraBlobs]:  # fmt: skip
    """Noise, flags and scan order (top row first), then one :class:`CameraBlobs` per camera.

    The hub flags a blob ``MERGED`` from its shape, as real hardware does: when its
    measured elongation exceeds :attr:`BlobModel.merge_elongation`. The measurement
    is noisier the smaller the blob (``shape_noise / d``), so two markers that
    nearly coincide pass as one round blob and a small single blob is now and then
    flagged; the truth's ``kind`` says what each blob really is.
    """
    n = image_size.shape[0]
    size = image_size[cam_of] - 1  # (N, 2)
    r = d / 2
    noisy = np.clip(true_uv + rng.normal(0.0, model.centroid_noise_px, true_uv.shape), 0, size)
    edge = (true_uv - r[:, None] < 0).any(axis=1) | (true_uv + r[:, None] > size).any(axis=1)
    measured = elong + np.abs(rng.normal(0.0, 1.0, elong.shape)) * model.shape_noise / d
    flags = (
        np.where(measured > model.merge_elongation, MERGED, 0).astype(np.uint8)
        | np.where(edge, EDGE, 0).astype(np.uint8)
        | np.where(pk > 255, SATURATED, 0).astype(np.uint8)
    )
    order = np.lexsort((true_uv[:, 0], true_uv[:, 1] - r, cam_of))
    bounds = np.searchsorted(cam_of[order], np.arange(n + 1))
    uv_o, area_o, pk_o = noisy[order], np.rint(area[order]), np.minimum(pk[order], 255.0)
    fl_o, mk_o, kd_o, tu_o = flags[order], marker[order], kind[order], true_uv[order]
    out = []
    for c in range(n):
        s = slice(int(bounds[c]), int(bounds[c + 1]))
        out.append(
            CameraBlobs(
                uv=uv_o[s], area=area_o[s], peak=pk_o[s], flags=fl_o[s], marker=mk_o[s],
                kind=kd_o[s], true_uv=tu_o[s], seen=seen[c],
            )
        )  # fmt: skip
    return out
