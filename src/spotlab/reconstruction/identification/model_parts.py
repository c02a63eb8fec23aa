"""The parts of a marker model: rigid clusters (segments) and distance links.

:class:`~spotlab.reconstruction.identification.model.MarkerModel` holds them; they live
apart so that the model's JSON layout (:mod:`.model_json`) can build them too.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["Link", "Segment"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Link:
    """Two markers whose distance stays within ``[min_mm, max_mm]``.

    Attributes
    ----------
    a, b : int
        Marker indices in :attr:`MarkerModel.labels`.
    min_mm, max_mm : float
        Range of their distance (mm).
    """

    a: int
    b: int
    min_mm: float
    max_mm: float


@dataclass(frozen=True)
class Segment:
    """One rigid cluster.

    Attributes
    ----------
    name : str
    markers : tuple of int
        Indices of its markers in :attr:`MarkerModel.labels` (at least 3).
    coordinates : ndarray, shape (P, 3)
        Marker positions in the segment's frame (mm), centred on their mean.
    """

    name: str
    markers: tuple[int, ...]
    coordinates: FloatArray
