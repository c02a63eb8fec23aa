"""A marker model: named markers grouped into rigid clusters (segments) with their layout.

Identification labels points by fitting these clusters (:mod:`.labelling`). A model is
learnt from labelled trajectories — a static trial, the first frames of a labelled
recording, a simulator's truth — either with the segments given or with the clusters
found as the groups of markers whose distances stay constant (:meth:`MarkerModel.infer`),
and kept as JSON.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.cluster.hierarchy import fcluster, linkage
from scipy.spatial.distance import squareform

from spotlab.core.errors import ReconstructionError
from spotlab.reconstruction.rigid import rigid_pose

__all__ = ["MarkerModel", "Segment"]

FloatArray = NDArray[np.float64]


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


@dataclass(frozen=True)
class MarkerModel:
    """Named markers on rigid clusters.

    Attributes
    ----------
    labels : tuple of str, length M
    segments : tuple of Segment
        Every marker belongs to exactly one segment.
    """

    labels: tuple[str, ...]
    segments: tuple[Segment, ...]

    def __post_init__(self) -> None:
        M = len(self.labels)
        if len(set(self.labels)) != M:
            raise ReconstructionError("marker labels must be unique")
        owner = np.full(M, -1)
        for s, seg in enumerate(self.segments):
            if len(seg.markers) < 3:
                raise ReconstructionError(
                    f"segment {seg.name!r} has {len(seg.markers)} markers: a rigid cluster "
                    "needs at least 3 to be identified by its shape"
                )
            if np.any(owner[list(seg.markers)] >= 0):
                raise ReconstructionError(f"segment {seg.name!r} shares markers with another")
            owner[list(seg.markers)] = s
        if np.any(owner < 0):
            lost = [self.labels[m] for m in np.flatnonzero(owner < 0)]
            raise ReconstructionError(f"markers on no segment: {', '.join(lost)}")

    @property
    def segment_of(self) -> NDArray[np.intp]:
        """Segment index of each marker, shape (M,)."""
        out = np.empty(len(self.labels), dtype=np.intp)
        for s, seg in enumerate(self.segments):
            out[list(seg.markers)] = s
        return out

    def pairs(self) -> tuple[NDArray[np.intp], NDArray[np.intp], FloatArray]:
        """Marker pairs of the same segment ``(i, j, distance mm)``, each once."""
        i_all, j_all, d_all = [], [], []
        for seg in self.segments:
            m = np.array(seg.markers)
            i, j = np.triu_indices(m.size, 1)
            i_all.append(m[i])
            j_all.append(m[j])
            d_all.append(np.linalg.norm(seg.coordinates[i] - seg.coordinates[j], axis=1))
        return np.concatenate(i_all), np.concatenate(j_all), np.concatenate(d_all)

    @classmethod
    def from_trajectories(
        cls, labels: Sequence[str], positions: Any, segments: Mapping[str, Sequence[str]]
    ) -> MarkerModel:
        """Learn each segment's layout from labelled trajectories.

        Parameters
        ----------
        labels : sequence of str, length M
        positions : array_like, shape (F, M, 3)
            Labelled marker positions (mm), NaN where missing.
        segments : mapping of str to sequence of str
            Segment name -> its marker labels.

        Returns
        -------
        MarkerModel
            Layouts averaged over the frames where all of a segment's markers are
            present, after fitting each such frame onto the first.

        Raises
        ------
        ReconstructionError
            For an unknown label, a segment never seen complete, or a bad shape.
        """
        labels = tuple(str(x) for x in labels)
        X = np.asarray(positions, dtype=np.float64)
        if X.ndim != 3 or X.shape[1:] != (len(labels), 3):
            raise ReconstructionError(f"positions must have shape (F, {len(labels)}, 3)")
        index = {name: m for m, name in enumerate(labels)}
        out = []
        for name, members in segments.items():
            unknown = [x for x in members if x not in index]
            if unknown:
                raise ReconstructionError(f"segment {name!r}: unknown markers {unknown}")
            m = [index[x] for x in members]
            frames = X[:, m]
            complete = frames[np.isfinite(frames).all(axis=(1, 2))]
            if complete.shape[0] == 0:
                raise ReconstructionError(f"segment {name!r} is never seen with all markers")
            first = complete[0] - complete[0].mean(axis=0)
            pose = rigid_pose(first, complete)
            local = np.einsum("fji,fpj->fpi", pose.R, complete - pose.t[:, None, :])
            coords = local[pose.valid].mean(axis=0) if pose.valid.any() else first
            out.append(Segment(str(name), tuple(m), coords - coords.mean(axis=0)))
        return cls(labels, tuple(out))

    @classmethod
    def infer(
        cls, labels: Sequence[str], positions: Any, *, tolerance_mm: float = 2.0
    ) -> MarkerModel:
        """Find the rigid clusters themselves: markers whose distances stay constant.

        Two markers are rigidly linked when the spread (max - min) of their distance
        over the frames where both are seen is below ``tolerance_mm``; a segment is a
        group in which every pair is linked (complete-linkage clustering of the
        spreads, cut at ``tolerance_mm``), so markers near a joint, linked to both
        neighbours, do not join two segments into one. A trial that hardly moves makes
        every marker look rigid: learn from one in which the segments move.

        Raises
        ------
        ReconstructionError
            When a group has fewer than 3 markers (it cannot be identified by shape).
        """
        labels = tuple(str(x) for x in labels)
        X = np.asarray(positions, dtype=np.float64)
        if X.ndim != 3 or X.shape[1:] != (len(labels), 3):
            raise ReconstructionError(f"positions must have shape (F, {len(labels)}, 3)")
        D = np.linalg.norm(X[:, :, None] - X[:, None], axis=-1)
        with np.errstate(invalid="ignore"):
            spread = np.nanmax(D, axis=0) - np.nanmin(D, axis=0)
        spread = np.nan_to_num(spread, nan=1e9)
        np.fill_diagonal(spread, 0.0)
        tree = linkage(squareform(np.maximum(spread, spread.T), checks=False), "complete")
        group = fcluster(tree, tolerance_mm, criterion="distance") - 1
        segments = {
            f"segment{g + 1}": [labels[m] for m in np.flatnonzero(group == g)]
            for g in np.unique(group)
        }
        small = {k: v for k, v in segments.items() if len(v) < 3}
        if small:
            raise ReconstructionError(
                "markers on no rigid cluster of 3 or more: "
                + "; ".join(", ".join(v) for v in small.values())
            )
        return cls.from_trajectories(labels, X, segments)

    def to_json(self) -> dict[str, Any]:
        """JSON-safe description (the file layout of :meth:`save`)."""
        return {
            "labels": list(self.labels),
            "segments": [
                {
                    "name": seg.name,
                    "markers": [self.labels[m] for m in seg.markers],
                    "coordinates_mm": seg.coordinates.round(4).tolist(),
                }
                for seg in self.segments
            ],
        }

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write the model as JSON."""
        with open(path, "w", encoding="utf-8") as fh:
            json.dump(self.to_json(), fh, indent=1)

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> MarkerModel:
        """Read a model written by :meth:`save`; a malformed file is a ReconstructionError."""
        try:
            with open(path, encoding="utf-8") as fh:
                data = json.load(fh)
            labels = tuple(str(x) for x in data["labels"])
            index = {name: m for m, name in enumerate(labels)}
            segments = tuple(
                Segment(
                    str(s["name"]),
                    tuple(index[str(x)] for x in s["markers"]),
                    np.asarray(s["coordinates_mm"], dtype=np.float64).reshape(-1, 3),
                )
                for s in data["segments"]
            )
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise ReconstructionError(f"{path}: not a marker model ({exc})") from None
        return cls(labels, segments)
