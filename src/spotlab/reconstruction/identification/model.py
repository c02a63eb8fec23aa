"""A marker model: named markers on rigid clusters (segments) and distance links.

Identification labels points by fitting these clusters (:mod:`.labelling`). Markers of a
real body are not all on rigid clusters (skin over a joint, a marker between two
segments): their distances to other markers vary within a range as the body moves.
Such pairs are kept as *links*, the range of the distance seen in a trial that moves
(minimum and maximum, mm); a marker on no cluster of three is labelled by its links
alone. A model is learnt from labelled trajectories — a range-of-motion trial, a
labelled recording, a simulator's truth — either with the segments given or with the
clusters found as the groups of markers whose distances stay constant
(:meth:`MarkerModel.infer`), and kept as JSON.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from functools import cached_property
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.cluster.hierarchy import fcluster, linkage
from scipy.spatial.distance import squareform

from spotlab.core.errors import ReconstructionError
from spotlab.reconstruction.identification.handedness import (
    Reference,
    learn_references,
    side_table,
)
from spotlab.reconstruction.identification.model_json import (
    model_to_json,
    read_model_fields,
    write_model,
)
from spotlab.reconstruction.identification.model_parts import Link, Segment
from spotlab.reconstruction.identification.spreads import (
    check_motion,
    least_varying,
    rigid_tolerance,
    robust_range,
)
from spotlab.reconstruction.rigid import rigid_pose

__all__ = ["Link", "MarkerModel", "Segment"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]

#: Links a marker on no rigid cluster needs to be labelled by its links alone.
MIN_LINKS = 3
#: A pair's spread counts (1 + length / this) times when clusters are formed: a long
#: pair that varies a little more likely crosses a joint the trial hardly moved.
LENGTH_SCALE_MM = 500.0
#: Chosen link spread: this many rigid tolerances, and at least ``LINK_FLOOR_MM``.
LINK_FACTOR = 5.0
LINK_FLOOR_MM = 50.0


@dataclass(frozen=True)
class MarkerModel:
    """Named markers on rigid clusters.

    Attributes
    ----------
    labels : tuple of str, length M
    segments : tuple of Segment
        Rigid clusters; a marker belongs to one at most.
    links : tuple of Link
        Distance ranges of marker pairs not on a common segment. A marker on no
        segment needs at least three.
    tolerance_mm : float or None
        Largest distance spread (mm) of the pairs taken as rigid when the clusters were
        found (:meth:`infer`); None when the segments were given.
    link_spread_mm : float or None
        Largest distance spread (mm) of the pairs taken as links; None: links not
        learnt by spread.
    references : tuple of Reference
        Markers off a flat cluster seen in a fixed cone of directions from its frame
        (:mod:`.handedness`): which way round the cluster sits, which its distances
        cannot tell. Learnt by :meth:`infer`; none for a model given otherwise.
    """

    labels: tuple[str, ...]
    segments: tuple[Segment, ...]
    links: tuple[Link, ...] = ()
    tolerance_mm: float | None = None
    link_spread_mm: float | None = None
    references: tuple[Reference, ...] = ()

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
        n_links = np.zeros(M, dtype=np.intp)
        for link in self.links:
            if not (0 <= link.a < M and 0 <= link.b < M) or link.a == link.b:
                raise ReconstructionError(f"link {link} does not join two of the {M} markers")
            if not 0.0 <= link.min_mm <= link.max_mm:
                raise ReconstructionError(f"link {link}: need 0 <= min_mm <= max_mm")
            n_links[[link.a, link.b]] += 1
        for ref in self.references:
            if not (0 <= ref.segment < len(self.segments) and 0 <= ref.marker < M):
                raise ReconstructionError(f"reference {ref} names an unknown segment or marker")
            if owner[ref.marker] == ref.segment:
                raise ReconstructionError(f"reference {ref} is a marker of its own segment")
            if ref.triple and (
                len(ref.triple) != 3 or any(owner[m] != ref.segment for m in ref.triple)
            ):
                raise ReconstructionError(f"reference {ref}: triple not of its segment")
        lost = np.flatnonzero((owner < 0) & (n_links < MIN_LINKS))
        if lost.size:
            raise ReconstructionError(
                "markers on no rigid cluster of 3 or more and with fewer than "
                f"{MIN_LINKS} distance links: {', '.join(self.labels[m] for m in lost)}"
            )

    @property
    def segment_of(self) -> NDArray[np.intp]:
        """Segment index of each marker, shape (M,); -1 for a marker on no segment."""
        out = np.full(len(self.labels), -1, dtype=np.intp)
        for s, seg in enumerate(self.segments):
            out[list(seg.markers)] = s
        return out

    @cached_property
    def segment_arrays(self) -> tuple[tuple[IntArray, FloatArray], ...]:
        """Each segment's ``(markers (P,), coordinates (P, 3))`` as arrays."""
        return tuple((np.array(s.markers, dtype=np.intp), s.coordinates) for s in self.segments)

    @cached_property
    def references_by_segment(self) -> dict[int, list[Reference]]:
        """:attr:`references` grouped by segment index (segments without none left out)."""
        out: dict[int, list[Reference]] = {}
        for ref in self.references:
            out.setdefault(ref.segment, []).append(ref)
        return out

    @cached_property
    def sides(self) -> tuple[IntArray, IntArray, FloatArray]:
        """:func:`.handedness.side_table` of :attr:`references` (built once)."""
        return side_table(self.references)

    @cached_property
    def intervals(self) -> tuple[IntArray, IntArray, FloatArray, FloatArray]:
        """Every constrained pair ``(i, j, min mm, max mm)``: segment pairs, then links.

        A segment pair's range is its model distance, widened by half the rigid
        tolerance the clusters were found with (:attr:`tolerance_mm`, when inferred):
        the pairs of a cluster varied by less than that tolerance, around their mean, so
        skin markers keep their labels through the skin motion the model was learnt
        with. Segments given by name (no tolerance) have min = max."""
        i, j, d = self.pairs()
        w = 0.0 if self.tolerance_mm is None else self.tolerance_mm / 2
        a = np.array([k.a for k in self.links], dtype=np.intp)
        b = np.array([k.b for k in self.links], dtype=np.intp)
        lo = np.array([k.min_mm for k in self.links], dtype=np.float64)
        hi = np.array([k.max_mm for k in self.links], dtype=np.float64)
        return (
            np.concatenate([i, a]),
            np.concatenate([j, b]),
            np.concatenate([np.maximum(d - w, 0.0), lo]),
            np.concatenate([d + w, hi]),
        )

    @cached_property
    def partners(self) -> tuple[tuple[IntArray, FloatArray, FloatArray], ...]:
        """Per marker, its constrained partners ``(partner, min mm, max mm)`` in the order
        of :attr:`intervals` (built once: labelling looks them up every frame)."""
        i, j, lo, hi = self.intervals
        out = []
        for m in range(len(self.labels)):
            sel = (i == m) | (j == m)
            out.append((np.where(i[sel] == m, j[sel], i[sel]), lo[sel], hi[sel]))
        return tuple(out)

    @cached_property
    def directed(self) -> tuple[IntArray, IntArray, FloatArray, FloatArray]:
        """:attr:`intervals` both ways round ``(marker, partner, min mm, max mm)``: every
        pair as ``(i, j)``, then every pair as ``(j, i)``."""
        i, j, lo, hi = self.intervals
        return (
            np.concatenate([i, j]),
            np.concatenate([j, i]),
            np.concatenate([lo, lo]),
            np.concatenate([hi, hi]),
        )

    def pairs(self) -> tuple[NDArray[np.intp], NDArray[np.intp], FloatArray]:
        """Marker pairs of the same segment ``(i, j, distance mm)``, each once."""
        i_all: list[IntArray] = [np.zeros(0, np.intp)]
        j_all: list[IntArray] = [np.zeros(0, np.intp)]
        d_all: list[FloatArray] = [np.zeros(0)]
        for seg in self.segments:
            m = np.array(seg.markers)
            i, j = np.triu_indices(m.size, 1)
            i_all.append(m[i])
            j_all.append(m[j])
            d_all.append(np.linalg.norm(seg.coordinates[i] - seg.coordinates[j], axis=1))
        return np.concatenate(i_all), np.concatenate(j_all), np.concatenate(d_all)

    @classmethod
    def from_trajectories(
        cls,
        labels: Sequence[str],
        positions: Any,
        segments: Mapping[str, Sequence[str]],
        *,
        link_spread_mm: float | None = None,
        min_links: int = 0,
    ) -> MarkerModel:
        """Learn each segment's layout (and links) from labelled trajectories.

        Parameters
        ----------
        labels : sequence of str, length M
        positions : array_like, shape (F, M, 3)
            Labelled marker positions (mm), NaN where missing.
        segments : mapping of str to sequence of str
            Segment name -> its marker labels (3 or more each).
        link_spread_mm : float, optional
            Link every pair of markers not on a common segment whose distance varies by
            less than this over the frames (its range seen is the link's). None: no
            links, every marker must be on a segment.
        min_links : int
            With ``link_spread_mm``: a marker on no segment with fewer links than this
            is also linked to its least varying partners until it has this many.

        Returns
        -------
        MarkerModel
            Layouts averaged over the frames where all of a segment's markers are
            present, after fitting each such frame onto the first.

        Raises
        ------
        ReconstructionError
            For an unknown label, a segment never seen complete, a bad shape, or a
            marker that can be labelled neither by a segment nor by its links.
        """
        labels = tuple(str(x) for x in labels)
        X = _positions(positions, len(labels))
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
        links: list[Link] = []
        if link_spread_mm is not None:
            lo, hi = robust_range(X)
            owner = np.full(len(labels), -1)
            for s, seg in enumerate(out):
                owner[list(seg.markers)] = s
            a, b = np.triu_indices(len(labels), 1)
            apart = (owner[a] < 0) | (owner[a] != owner[b])
            keep = (hi[a, b] - lo[a, b] < link_spread_mm) & apart
            if min_links > 0:
                keep |= least_varying(lo, hi, owner, a, b, keep, apart, min_links)
            links = [
                Link(int(i), int(j), float(lo[i, j]), float(hi[i, j]))
                for i, j in zip(a[keep], b[keep], strict=True)
            ]
        return cls(labels, tuple(out), tuple(links))

    @classmethod
    def infer(
        cls,
        labels: Sequence[str],
        positions: Any,
        *,
        tolerance_mm: float | None = None,
        link_spread_mm: float | None = None,
    ) -> MarkerModel:
        """Find the rigid clusters themselves: markers whose distances stay constant.

        Two markers are rigidly linked when the spread (max - min) of their distance
        over the frames where both are seen, weighted by ``1 + length / 500 mm`` (length:
        their largest distance), is below ``tolerance_mm``; a segment is a
        group of 3 or more in which every pair is linked (complete-linkage clustering of
        the spreads, cut at ``tolerance_mm``), so markers near a joint, linked to both
        neighbours, do not join two segments into one. The length weight keeps apart
        far markers whose distance a trial hardly changed (the head and the sacrum in
        the first strides of a walk: they are not one rigid body, and out of sample
        their distance varies with the trunk's flexion, in proportion to their length);
        exactly rigid markers (spread 0) are not affected. Pairs whose distance varies by
        less than ``link_spread_mm`` become links (see :meth:`from_trajectories`) and
        markers on no cluster of 3 are labelled by them; a group on a line (its rotation
        about the line unknown) is no segment either.

        Parameters
        ----------
        labels : sequence of str, length M
        positions : array_like, shape (F, M, 3)
            Labelled trajectories (mm), NaN where missing.
        tolerance_mm : float, optional
            Largest spread of a rigid pair (mm). Default: chosen from the trial
            (:func:`rigid_tolerance`): twice the median, over the markers, of each
            marker's second-smallest spread, and at least 2 mm.
        link_spread_mm : float, optional
            Largest spread of a link (mm); 0 for no links (every marker must then be on
            a cluster). Default: ``5 * tolerance_mm``, at least 50 mm, and every marker
            off the clusters also linked to its 3 least varying partners, so that it
            can be labelled by its links.

        Returns
        -------
        MarkerModel
            With the tolerance and link spread it was learnt with
            (:attr:`MarkerModel.tolerance_mm`, :attr:`MarkerModel.link_spread_mm`).

        Raises
        ------
        ReconstructionError
            For a trial that hardly moves (most distances constant: every marker looks
            rigid; learn from a trial in which the segments move through their range),
            or a marker on no cluster of 3 or more with fewer than 3 links.
        """
        labels = tuple(str(x) for x in labels)
        X = _positions(positions, len(labels))
        lo, hi = robust_range(X)
        spread = np.nan_to_num(hi - lo, nan=1e9)
        np.fill_diagonal(spread, 0.0)
        spread = np.maximum(spread, spread.T)
        if tolerance_mm is None:
            tolerance_mm = rigid_tolerance(spread)
            check_motion(spread, tolerance_mm)
        if link_spread_mm is None:
            link_spread_mm = max(LINK_FLOOR_MM, LINK_FACTOR * tolerance_mm)
            min_links = MIN_LINKS
        else:
            min_links = 0
        length = np.nan_to_num(np.maximum(hi, hi.T), nan=0.0)
        np.fill_diagonal(length, 0.0)
        weighted = spread * (1.0 + length / LENGTH_SCALE_MM)
        tree = linkage(squareform(weighted, checks=False), "complete")
        group = fcluster(tree, tolerance_mm, criterion="distance") - 1
        groups = [[labels[m] for m in np.flatnonzero(group == g)] for g in np.unique(group)]
        small = [g for g in groups if len(g) < 3]
        if small and link_spread_mm <= 0:
            raise ReconstructionError(
                "markers on no rigid cluster of 3 or more: "
                + "; ".join(", ".join(v) for v in small)
                + " (give link_spread_mm to label them by their distance links)"
            )
        index = {name: m for m, name in enumerate(labels)}
        solid = [g for g in groups if len(g) >= 3 and _spans_a_plane(X[:, [index[x] for x in g]])]
        if len(solid) < len(groups) - len(small) and link_spread_mm <= 0:
            raise ReconstructionError(
                "markers on a line cannot make a rigid cluster: "
                + "; ".join(", ".join(g) for g in groups if len(g) >= 3 and g not in solid)
                + " (give link_spread_mm to label them by their distance links)"
            )
        segments = {f"segment{k + 1}": g for k, g in enumerate(solid)}
        model = cls.from_trajectories(
            labels,
            X,
            segments,
            link_spread_mm=link_spread_mm if link_spread_mm > 0 else None,
            min_links=min_links,
        )
        return replace(
            model,
            tolerance_mm=float(tolerance_mm),
            link_spread_mm=float(link_spread_mm) if link_spread_mm > 0 else None,
            references=learn_references(model.segment_arrays, X, float(tolerance_mm)),
        )

    def to_json(self) -> dict[str, Any]:
        """JSON-safe description (the file layout of :meth:`save`,
        :func:`~.model_json.model_to_json`)."""
        return model_to_json(self)

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write the model as JSON."""
        write_model(self, path)

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> MarkerModel:
        """Read a model written by :meth:`save`; a malformed file is a ReconstructionError."""
        labels, segments, links, tolerance, link_spread, references = read_model_fields(path)
        return cls(labels, segments, links, tolerance, link_spread, references=references)


def _positions(positions: Any, M: int) -> FloatArray:
    """Trajectories as float (F, M, 3), or a ReconstructionError."""
    X = np.asarray(positions, dtype=np.float64)
    if X.ndim != 3 or X.shape[1:] != (M, 3):
        raise ReconstructionError(f"positions must have shape (F, {M}, 3)")
    return X


def _spans_a_plane(X: FloatArray, min_mm: float = 10.0) -> bool:
    """Whether markers (F, P, 3) stand more than ``min_mm`` (RMS) off their best line in
    their first complete frame: a rigid fit needs three non-collinear markers."""
    complete = X[np.isfinite(X).all(axis=(1, 2))]
    if complete.shape[0] == 0:
        return False
    centred = complete[0] - complete[0].mean(axis=0)
    off_line = np.linalg.svd(centred, compute_uv=False)[1] / np.sqrt(centred.shape[0])
    return bool(off_line > min_mm)
