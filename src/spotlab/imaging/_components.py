"""Connected components of the bright pixels of a frame, labelled per bright pixel.

Marker frames are almost black: a few thousand of a million pixels pass the
threshold. Labelling the whole frame (``scipy.ndimage.label``, ~2 ms for
1280x800) costs more than the rest of the centroiding, so sparse frames are
labelled as a graph of their bright pixels only (edges to the 8-connected
neighbours that follow in raster order, ``scipy.sparse.csgraph``), and dense
frames (sunlight) fall back to ``ndimage.label``, whose time does not grow
with the number of bright pixels.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import scipy.ndimage
import scipy.sparse
from scipy.sparse.csgraph import connected_components

I64 = npt.NDArray[np.int64]

#: Above this share of bright pixels the whole-frame labelling is the faster one.
DENSE_FRACTION = 1.0 / 32.0
_EIGHT = np.ones((3, 3), dtype=bool)


def label_bright(
    bright: npt.NDArray[np.bool_], index: I64, *, dense_fraction: float = DENSE_FRACTION
) -> tuple[I64, int]:
    """8-connected components of the bright pixels.

    Parameters
    ----------
    bright : ndarray of bool, shape (H, W)
        Pixels above the threshold.
    index : ndarray of int64, shape (n,)
        Raster indices of the ``True`` pixels of ``bright``, increasing
        (``np.flatnonzero(bright)``).
    dense_fraction : float, optional
        Share of bright pixels above which the whole frame is labelled at once.

    Returns
    -------
    labels : ndarray of int64, shape (n,)
        Component of each bright pixel, ``0 .. count - 1``, numbered in raster order
        of each component's first pixel.
    count : int
        Number of components.
    """
    n = int(index.shape[0])
    if n == 0:
        return np.zeros(0, np.int64), 0
    height, width = bright.shape
    if n > dense_fraction * height * width:
        image_labels, count = scipy.ndimage.label(bright, structure=_EIGHT)
        # ndimage numbers components in raster order of their first pixel, from 1.
        return image_labels.ravel()[index].astype(np.int64) - 1, int(count)
    return _label_graph(bright.ravel(), index, width)


def _label_graph(flat: npt.NDArray[np.bool_], index: I64, width: int) -> tuple[I64, int]:
    n = int(index.shape[0])
    size = flat.shape[0]
    col = index % width
    sources: list[I64] = []
    targets: list[I64] = []
    # Forward neighbours only (right, down-left, down, down-right): each edge once.
    for offset, col_ok in (
        (1, col < width - 1),
        (width - 1, col > 0),
        (width, None),
        (width + 1, col < width - 1),
    ):
        near = index + offset
        ok = near < size
        if col_ok is not None:
            ok &= col_ok
        ok[ok] = flat[near[ok]]
        src = np.flatnonzero(ok)
        sources.append(src)
        targets.append(np.searchsorted(index, near[src]))
    src_all = np.concatenate(sources)
    dst_all = np.concatenate(targets)
    graph = scipy.sparse.csr_matrix(
        (np.ones(src_all.shape[0], np.int8), (src_all, dst_all)), shape=(n, n)
    )
    count, labels = connected_components(graph, directed=False)
    labels = labels.astype(np.int64)
    # Renumber in raster order of each component's first pixel (csgraph does not promise it).
    first = np.full(count, n, np.int64)
    np.minimum.at(first, labels, np.arange(n, dtype=np.int64))
    rank = np.empty(count, np.int64)
    rank[np.argsort(first, kind="stable")] = np.arange(count, dtype=np.int64)
    return rank[labels], int(count)
