"""Several scanners in one frame, from a rigid object they all see (issue 18).

Each scanner reports 3-D in its own frame (:mod:`spotlab.reconstruction.scanner`).
A static rigid object with markers of known codes (an L-frame on a stand) seen by
two units gives, in each frame, the object's marker positions (the median over the
frames of a recording); the least-squares rigid motion between them
(:func:`~spotlab.reconstruction.rigid.rigid_fit`, with the reflection guard) carries
the second unit's trajectories into the first unit's frame:
``p_a = R p_b + t``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from spotlab.processing.errors import InputError
from spotlab.reconstruction.rigid import rigid_fit

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class Alignment:
    """A rigid motion from one scanner's frame into another's.

    Attributes
    ----------
    R : ndarray, shape (3, 3)
        Rotation, det +1.
    t : ndarray, shape (3,)
        Translation (mm).
    rms : float
        RMS distance of the reference markers after the fit (mm).
    labels : tuple of str
        The reference markers used.
    """

    R: F64
    t: F64
    rms: float
    labels: tuple[str, ...]

    def apply(self, points: F64) -> F64:
        """Points (..., 3) of the moved unit's frame in the reference unit's frame."""
        return points @ self.R.T + self.t


def reference_positions(points: F64, labels: Sequence[str], wanted: Sequence[str]) -> F64:
    """Median position (P, 3) of each ``wanted`` marker over the frames; NaN if never seen.

    Parameters
    ----------
    points : ndarray, shape (F, M, 3)
        A scanner's trajectories (mm), NaN where missing.
    labels : sequence of str, length M
        Their marker codes.
    wanted : sequence of str
        The reference object's marker codes.
    """
    out = np.full((len(wanted), 3), np.nan)
    for i, code in enumerate(wanted):
        if code in labels:
            column = points[:, list(labels).index(code)]
            seen = np.isfinite(column).all(axis=1)
            if seen.any():
                out[i] = np.median(column[seen], axis=0)
    return out


def align_scanners(
    points_a: F64,
    labels_a: Sequence[str],
    points_b: F64,
    labels_b: Sequence[str],
    reference: Sequence[str],
) -> Alignment:
    """The rigid motion carrying scanner B's frame into scanner A's.

    Raises
    ------
    InputError
        When fewer than 3 reference markers are seen by both units, or they are
        collinear; the message names the markers missing.
    """
    ref_a = reference_positions(points_a, labels_a, reference)
    ref_b = reference_positions(points_b, labels_b, reference)
    both = np.asarray(np.isfinite(ref_a).all(axis=1) & np.isfinite(ref_b).all(axis=1))
    if both.sum() < 3:
        missing = [c for c, ok in zip(reference, both.tolist(), strict=True) if not ok]
        raise InputError(
            f"aligning scanners needs 3 reference markers seen by both; not seen by both: "
            f"{', '.join(missing)}"
        )
    R, t, rms = rigid_fit(ref_b[both], ref_a[both][None])
    if not np.isfinite(rms[0]):
        raise InputError("the reference markers seen by both scanners are collinear")
    used = tuple(c for c, ok in zip(reference, both.tolist(), strict=True) if ok)
    return Alignment(R[0], t[0], float(rms[0]), used)
