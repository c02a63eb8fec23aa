"""Units used throughout spotlab and conversions at the edges.

Lengths are millimetres, image coordinates pixels (or detector counts for
lateral photodiodes), angles radians inside the numerics, timestamps int64
nanoseconds, durations inside the numerics float seconds.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

NS_PER_S = 1_000_000_000
NS_PER_US = 1_000
US_PER_S = 1_000_000


def seconds_to_ns(seconds: float) -> int:
    """Convert seconds to integer nanoseconds, rounding to the nearest."""
    return round(seconds * NS_PER_S)


def ns_to_seconds(ns: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Convert int64 nanoseconds to float seconds.

    Parameters
    ----------
    ns : array_like of int
        Timestamps in nanoseconds, any shape.

    Returns
    -------
    ndarray of float64
        The same instants in seconds, same shape.
    """
    return np.asarray(ns, dtype=np.int64).astype(np.float64) / NS_PER_S
