"""Image coordinates of an ``image2d`` stream's frames, NaN where a reading is unusable.

The rule for lateral-photodiode (PSD) detector counts, shared by the live pipeline and
the processing layer's reading of recordings
(``spotlab.processing.recorded_observations``):

- a reading the device flagged not valid is NaN already;
- a reading the device flagged saturated (SPX flag ``0x02``,
  ``docs/protocols/selspot.md``) is dropped: saturation pulls it towards the centre;
- a reading on the detector's edge, 0 or 4094 counts, is dropped: it was clipped, the
  light fell further out.

Streams whose ``x`` and ``y`` are not detector counts keep their values (NaN where
missing).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from spotlab.core.streams import StreamSpec

__all__ = [
    "FLAG_SATURATED",
    "PSD_MAX_COUNT",
    "is_psd_counts",
    "pixels",
    "pixels_by_marker",
    "usable_counts",
]

FloatArray = NDArray[np.float64]

#: Largest detector count a reading can take; a reading there (or at 0) was clipped.
PSD_MAX_COUNT = 4094.0
#: SPX record flag: the ADC saturated (``docs/protocols/selspot.md``).
FLAG_SATURATED = 0x02


def usable_counts(data: FloatArray, flags: NDArray[np.uint8]) -> FloatArray:
    """Detector counts (F, M, C, 2) of ``data`` (F, M, C, >=2), NaN where unusable.

    Not valid (NaN already), saturated, and clipped (0 or 4094 counts) readings are
    dropped (see the module docstring).
    """
    uv = data[..., :2].copy()
    unusable = (flags & FLAG_SATURATED) != 0
    unusable |= ((uv == 0) | (uv == PSD_MAX_COUNT)).any(axis=-1)
    uv[unusable] = np.nan
    return uv


def is_psd_counts(spec: StreamSpec) -> bool:
    """Whether a stream's first two values are PSD detector counts (``x``, ``y`` in counts)."""
    return spec.values[:2] == ("x", "y") and spec.units[:2] == ("count", "count")


def pixels(spec: StreamSpec, data: FloatArray, flags: NDArray[np.uint8]) -> FloatArray:
    """Image coordinates per frame, camera and marker, shape (F, S, M, 2).

    Parameters
    ----------
    spec : StreamSpec
        The ``image2d`` stream (its first two values are ``x`` and ``y``).
    data : ndarray, shape (F, M, S, V)
        A frame block's values.
    flags : ndarray of uint8, shape (F, M, S)
        Its quality flags.

    Returns
    -------
    ndarray, shape (F, S, M, 2)
        ``x, y``; NaN where missing, and for PSD counts where unusable.
    """
    return np.ascontiguousarray(pixels_by_marker(spec, data, flags).transpose(0, 2, 1, 3))


def pixels_by_marker(spec: StreamSpec, data: FloatArray, flags: NDArray[np.uint8]) -> FloatArray:
    """:func:`pixels` in the block's own layout, shape (F, M, S, 2).

    Parameters
    ----------
    spec : StreamSpec
        The ``image2d`` stream.
    data : ndarray, shape (F, M, S, V)
        A frame block's values.
    flags : ndarray of uint8, shape (F, M, S)
        Its quality flags.

    Returns
    -------
    ndarray, shape (F, M, S, 2)
        ``x, y``, NaN where unusable: a view of ``data`` (no copy) unless the stream
        holds PSD counts.
    """
    return usable_counts(data, flags) if is_psd_counts(spec) else data[..., :2]
