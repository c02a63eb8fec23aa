"""How well labelled trajectories fit a marker model, marker by marker.

A marker's residual in one frame, against one of its constrained pairs
(:attr:`.model.MarkerModel.intervals`: segment mates and links), is how far their
distance falls outside the pair's range (0 inside; for segment mates the range is the
model distance). :func:`model_fit` gathers, per marker, the RMS and the largest of these
over every frame and pair in which both markers are seen: a marker placed elsewhere, a
swapped label or a model of another subject shows as residuals far beyond the few mm of
skin motion.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from spotlab.core.errors import ReconstructionError
from spotlab.reconstruction.identification.model import MarkerModel

__all__ = ["ModelFit", "model_fit"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class ModelFit:
    """Distance residuals of a trial against a model, per marker (model label order).

    Attributes
    ----------
    labels : tuple of str, length M
    rms_mm : ndarray, shape (M,)
        RMS residual (mm) over frames and constrained pairs; NaN where never checked.
    max_mm : ndarray, shape (M,)
        Largest residual (mm); NaN where never checked.
    worst_frame : ndarray of int, shape (M,)
        Frame (index into the positions) of the largest residual; -1 where none.
    checks : ndarray of int, shape (M,)
        (frame, pair) residuals behind each figure.
    seen : ndarray of float, shape (M,)
        Share of frames in which the marker is present.
    """

    labels: tuple[str, ...]
    rms_mm: FloatArray
    max_mm: FloatArray
    worst_frame: NDArray[np.intp]
    checks: NDArray[np.intp]
    seen: FloatArray

    @property
    def worst(self) -> int:
        """Index of the marker with the largest RMS residual (-1 if none was checked)."""
        if not np.isfinite(self.rms_mm).any():
            return -1
        return int(np.nanargmax(self.rms_mm))


def model_fit(model: MarkerModel, labels: Sequence[str], positions: Any) -> ModelFit:
    """Residuals of labelled trajectories against ``model``.

    Parameters
    ----------
    model : MarkerModel
    labels : sequence of str, length L
        Labels of the trajectories (any order; more than the model's are ignored).
    positions : array_like, shape (F, L, 3)
        Trajectories (mm), NaN where missing.

    Returns
    -------
    ModelFit

    Raises
    ------
    ReconstructionError
        When the trajectories lack some of the model's labels, or for a bad shape.
    """
    names = [str(x) for x in labels]
    X = np.asarray(positions, dtype=np.float64)
    if X.ndim != 3 or X.shape[1:] != (len(names), 3):
        raise ReconstructionError(f"positions must have shape (F, {len(names)}, 3)")
    index = {name: k for k, name in enumerate(names)}
    missing = [name for name in model.labels if name not in index]
    if missing:
        raise ReconstructionError(
            f"the trial lacks {len(missing)} of the model's {len(model.labels)} markers: "
            + ", ".join(missing)
        )
    Y = X[:, [index[name] for name in model.labels]]  # (F, M, 3)
    M = len(model.labels)
    i, j, lo, hi = model.intervals
    dist = np.linalg.norm(Y[:, i] - Y[:, j], axis=2)  # (F, P)
    err = np.maximum(np.maximum(lo - dist, dist - hi), 0.0)
    ok = np.isfinite(err)
    sq = np.where(ok, err, 0.0) ** 2
    total = np.bincount(i, sq.sum(axis=0), M) + np.bincount(j, sq.sum(axis=0), M)
    checks = (np.bincount(i, ok.sum(axis=0), M) + np.bincount(j, ok.sum(axis=0), M)).astype(np.intp)
    with np.errstate(invalid="ignore", divide="ignore"):
        rms = np.where(checks > 0, np.sqrt(total / checks), np.nan)
    worst = np.where(ok, err, -1.0)
    best_max = np.full(M, np.nan)
    best_frame = np.full(M, -1, dtype=np.intp)
    if worst.size:
        frame_of = np.argmax(worst, axis=0)  # per pair
        value = worst[frame_of, np.arange(worst.shape[1])]
        for m in range(M):
            mine = np.flatnonzero(((i == m) | (j == m)) & (value >= 0))
            if mine.size:
                p = mine[np.argmax(value[mine])]
                best_max[m], best_frame[m] = value[p], frame_of[p]
    seen = np.isfinite(Y).all(axis=2).mean(axis=0) if Y.shape[0] else np.zeros(M, dtype=np.float64)
    return ModelFit(
        labels=model.labels,
        rms_mm=np.asarray(rms, dtype=np.float64),
        max_mm=best_max,
        worst_frame=best_frame,
        checks=checks,
        seen=np.asarray(seen, dtype=np.float64),
    )
