"""The motion interface of the simulators: where is each marker at each instant.

Every motion answers one vectorised question, :meth:`Motion.sample`: where was
marker ``markers[i]`` at time ``times[i]``? World frame: mm, z up, floor at z = 0.
NaN means the marker does not exist at that moment; the device reports it as not seen.
The motions themselves are in :mod:`spotlab.simulators.motions` and
:mod:`spotlab.simulators.walking_body`.
"""

from __future__ import annotations

from abc import ABC, abstractmethod

import numpy as np
import numpy.typing as npt

__all__ = ["F64", "I64", "Motion"]

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]


class Motion(ABC):
    """Trajectories of ``n_markers`` markers.

    Attributes
    ----------
    n_markers : int
        Number of markers; marker ``i`` is carried by LED id ``i``.
    labels : tuple of str
        One label per marker.
    """

    n_markers: int
    labels: tuple[str, ...]

    @abstractmethod
    def sample(self, times: F64, markers: I64) -> F64:
        """Positions of ``markers`` (K,) at ``times`` (K,) seconds -> (K, 3) mm, NaN if missing."""

    def positions(self, t: float) -> F64:
        """All markers at one time ``t`` seconds -> (M, 3) mm."""
        m = np.arange(self.n_markers, dtype=np.int64)
        return self.sample(np.full(self.n_markers, float(t)), m)
