"""A standing pose from a gait trial: each leg at its mid-stance, under one pelvis.

Gait trials have no standing frame. :func:`mid_stance_pose` builds a neutral pose from
one: each leg is taken from its mid-stance — of the frames in which its foot is flat on
the floor (heel and toe within ``flat_mm`` of their own lowest), the one with its ankle
nearest below the pelvis — in the pelvis frame of that frame (origin between the ASIS,
x forward from the sacrum, z the lab's up) and at that frame's heights; the pelvis
markers are their mean in the pelvis frame. The result is in a body frame (x forward,
y left, z up, the floor of the lab at z = 0, the pelvis over the origin): what a
:class:`~spotlab.reconstruction.identification.template.Template` holds, and what a
static trial of the subject would roughly show.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from spotlab.core.errors import ReconstructionError

__all__ = ["mid_stance_pose", "pelvis_frame"]

FloatArray = NDArray[np.float64]
PELVIS = ("LASI", "RASI", "SACR")
LEG = ("THI", "KNE", "TIB", "ANK", "HEE", "TOE")


def pelvis_frame(X: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Origin (F, 3) and axes (F, 3, 3) (rows: forward, left, up) of the pelvis from its
    markers ``X`` (F, 3, 3) (LASI, RASI, SACR; mm, z up)."""
    origin = 0.5 * (X[:, 0] + X[:, 1])
    fwd = origin - X[:, 2]
    fwd[:, 2] = 0.0
    with np.errstate(invalid="ignore", divide="ignore"):
        fwd /= np.linalg.norm(fwd, axis=1, keepdims=True)
    up = np.broadcast_to([0.0, 0.0, 1.0], fwd.shape)
    return origin, np.stack([fwd, np.cross(up, fwd), up], axis=1)


def mid_stance_pose(labels: Sequence[str], positions: Any, *, flat_mm: float = 25.0) -> FloatArray:
    """The standing pose (M, 3) mm of a gait trial (see the module docstring).

    Parameters
    ----------
    labels : sequence of str, length M
        Must hold LASI, RASI, SACR and, per side (L, R), ANK and TOE; the other
        markers of the set THI KNE TIB HEE are placed with their side's leg (without a
        heel marker the ankle's height stands for it), any other marker is NaN.
    positions : array_like, shape (F, M, 3)
        The trial (mm, z up, floor at z = 0), NaN where missing.
    flat_mm : float
        A foot is flat with its heel and toe within this of their lowest heights (mm).

    Raises
    ------
    ReconstructionError
        For missing markers or a foot never flat with its leg complete.
    """
    labels = list(labels)
    X = np.asarray(positions, dtype=np.float64)
    need = [*PELVIS, *(s + n for s in "LR" for n in ("ANK", "TOE"))]
    missing = [n for n in need if n not in labels]
    if missing or X.ndim != 3 or X.shape[1:] != (len(labels), 3):
        raise ReconstructionError(
            f"need a gait trial (F, M, 3) with {', '.join(need)}; missing {missing}"
        )
    pel = [labels.index(n) for n in PELVIS]
    origin, axes = pelvis_frame(X[:, pel])
    local = np.einsum("fij,fmj->fmi", axes, X - origin[:, None])
    out = np.full((len(labels), 3), np.nan)
    heights = []
    for side in "LR":
        rows = [labels.index(side + n) for n in LEG if side + n in labels]
        toe, ank = labels.index(side + "TOE"), labels.index(side + "ANK")
        hee = labels.index(side + "HEE") if side + "HEE" in labels else ank
        ok = np.isfinite(local[:, rows + pel]).all(axis=(1, 2))
        if not ok.any():
            raise ReconstructionError(f"the {side} leg is never complete with the pelvis")
        low = np.nanmin(X[ok][:, [hee, toe], 2], axis=0)
        flat = ok & (X[:, hee, 2] < low[0] + flat_mm) & (X[:, toe, 2] < low[1] + flat_mm)
        if not flat.any():
            raise ReconstructionError(f"the {side} foot is never flat on the floor")
        f = int(np.flatnonzero(flat)[np.argmin(np.abs(local[flat, ank, 0]))])
        out[rows] = local[f, rows]
        out[rows, 2] += origin[f, 2]
        heights.append(origin[f, 2])
    out[pel] = np.nanmean(local[:, pel], axis=0)
    out[pel, 2] += float(np.mean(heights))
    out[:, :2] -= out[pel, :2].mean(axis=0)
    return out
