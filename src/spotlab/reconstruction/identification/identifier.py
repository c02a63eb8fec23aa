"""Frame-by-frame identification: blobs -> labelled 3-D markers.

One :class:`Identifier` per recording or live stream. Per frame:

1. cameras with more blobs than ``max_blobs`` (sunlight, a lamp) or flagged unusable
   by the caller are left out of the frame and flagged;
2. blobs are undistorted once; tracked points are predicted, projected and given their
   blobs (:func:`.tracking.associate`), then triangulated with outlier rays dropped;
3. blobs no track explains are matched across cameras (:func:`.match_blobs`) into new
   unlabelled tracks; those below the floor are reflections (ghosts), tracked but never
   labelled;
4. labels are checked against their clusters and given to unlabelled points
   (:mod:`.labelling`);
5. over every ``check_frames`` frames, a camera whose blobs the others hardly ever
   confirm means the calibration does not match the cameras: a :class:`CalibrationError`
   names it rather than labels being made up from the rest.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from spotlab.core.errors import ReconstructionError
from spotlab.geometry import Rig
from spotlab.reconstruction.identification.blobs import BlobFrame
from spotlab.reconstruction.identification.calibration_check import CalibrationCheck
from spotlab.reconstruction.identification.correspondence import match_blobs
from spotlab.reconstruction.identification.crossed_rays import crossed_rays
from spotlab.reconstruction.identification.duplicate_tracks import duplicate_tracks
from spotlab.reconstruction.identification.geometry import RigGeometry, camera_slots
from spotlab.reconstruction.identification.handedness import misplaced_segments
from spotlab.reconstruction.identification.identified_frame import (
    FLOODED,
    NO_BLOBS,
    UNUSABLE,
    IdentifiedFrame,
)
from spotlab.reconstruction.identification.labelling import assign_labels, inconsistent_labels
from spotlab.reconstruction.identification.model import MarkerModel
from spotlab.reconstruction.identification.reference_pairs import (
    exchanged_references,
    reference_pairs,
)
from spotlab.reconstruction.identification.tracking import Tracks, associate
from spotlab.reconstruction.identification.twin_clusters import refuted_twins, twin_partners

__all__ = ["Identifier"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]


class Identifier:
    """Label the markers of a marker model in blob frames of a calibrated rig.

    Parameters
    ----------
    rig : Rig
        The calibration (mm) of the cameras, in the order of the blobs' camera indices.
    model : MarkerModel
        Markers and rigid clusters to label.
    floor_mm : float or None
        Height of the floor; points below it are reflections. None: no floor.
    gate_px : float
        Association gate of a track seen in the previous frame (undistorted px); it
        grows by this much per missed frame.
    ray_px : float
        Largest ray error of a kept ray (undistorted px); about 5x the centroid noise.
    epipolar_px : float
        Gate of the epipolar search for new points (px).
    min_cameras : int
        Cameras a new point needs (a tracked one needs 2).
    bridge_frames : int
        Frames a track is carried through without measurement before it is deleted.
    keep_label_frames : int
        A track found again after at most this many missed frames keeps its label;
        after a longer gap the label is given again by the cluster fit or the links.
    tol_mm, rms_mm, margin_mm : float
        Cluster checks: tolerance of model distances, largest RMS of an accepted
        identity, smallest lead over the runner-up (see :func:`.assign_labels`).
    max_blobs : int
        More blobs than this in one camera and frame leave the camera out of the frame.
    check_frames : int
        Window of the calibration check (frames); 0 turns it off.
    apart_mm : float
        Two points closer than this (mm) are one marker: an unlabelled track that close
        to a labelled one is deleted (:func:`.duplicate_tracks.duplicate_tracks`). Less
        than the smallest passive marker's diameter; 0 turns it off.

    Raises
    ------
    ReconstructionError
        For a rig that is not a Rig or options out of range.
    """

    def __init__(
        self,
        rig: Rig,
        model: MarkerModel,
        *,
        floor_mm: float | None = 0.0,
        gate_px: float = 3.0,
        ray_px: float = 1.0,
        epipolar_px: float = 1.5,
        min_cameras: int = 3,
        bridge_frames: int = 30,
        keep_label_frames: int = 3,
        tol_mm: float = 5.0,
        rms_mm: float = 3.0,
        margin_mm: float = 1.0,
        max_blobs: int = 400,
        check_frames: int = 150,
        apart_mm: float = 4.0,
    ) -> None:
        if not isinstance(rig, Rig):
            raise ReconstructionError(f"rig must be a spotlab Rig, got {type(rig).__name__}")
        if min(gate_px, ray_px, epipolar_px, tol_mm, rms_mm) <= 0 or max_blobs < 1:
            raise ReconstructionError("gates, tolerances and max_blobs must be positive")
        self.geom = RigGeometry(rig)
        self.model = model
        self.floor_mm = floor_mm
        self.gate_px, self.ray_px, self.epipolar_px = gate_px, ray_px, epipolar_px
        self.min_cameras, self.bridge_frames = min_cameras, bridge_frames
        self.keep_label_frames = keep_label_frames
        self.tol_mm, self.rms_mm, self.margin_mm = tol_mm, rms_mm, margin_mm
        self.max_blobs, self.check_frames = max_blobs, check_frames
        self.apart_mm = apart_mm
        self.tracks = Tracks()
        S = len(model.segments)
        self._anchors = np.full((S, 3), np.nan)
        self._segment_of = model.segment_of
        _ = model.partners, model.directed  # the model's lookup tables, built before frames
        self._points = np.full((len(model.labels), 3), np.nan)  # labelled points (checks)
        self._twin_partners = twin_partners(model, tol_mm)
        self._twins = tuple(self._twin_partners)
        self._pairs = reference_pairs(model)
        self._check_calibration = CalibrationCheck(rig, check_frames)
        self._crossed = np.zeros(0, dtype=bool)  # per track (:mod:`.crossed_rays`)

    def __call__(
        self, frame: BlobFrame, unusable: NDArray[np.bool_] | None = None
    ) -> IdentifiedFrame:
        """Identify one frame.

        Parameters
        ----------
        frame : BlobFrame
            Blobs of this frame, camera indices in rig order.
        unusable : ndarray of bool, shape (C,), optional
            Cameras to leave out (offline, overflowing), as their hub flags them.

        Returns
        -------
        IdentifiedFrame

        Raises
        ------
        ReconstructionError
            For blobs of a camera the rig lacks.
        CalibrationError
            When, over the check window, some camera's blobs are hardly ever confirmed
            by the others: the calibration does not match the cameras.
        """
        C = len(self.geom)
        counts = frame.counts(C)
        flags: IntArray = np.where(counts > self.max_blobs, FLOODED, 0).astype(np.intp)
        flags |= np.where(counts == 0, NO_BLOBS, 0)
        if unusable is not None:
            flags |= np.where(np.asarray(unusable, dtype=bool).reshape(C), UNUSABLE, 0)
        camera, uv, merged = frame.camera, frame.uv, frame.merged
        if (flags & (FLOODED | UNUSABLE)).any():
            keep = (flags & (FLOODED | UNUSABLE))[camera] == 0
            camera, uv, merged = camera[keep], uv[keep], merged[keep]
        slots = camera_slots(camera, C)
        xy, ok = self.geom.normalize(uv, camera, slots)
        usable = ok & ~merged
        tracks = self.tracks
        gate = np.asarray(self.gate_px * (1.0 + tracks.missed), dtype=np.float64)
        index, near = associate(self.geom, tracks.predict(), gate, xy, camera, usable, slots)
        seen = index >= 0
        if xy.shape[0]:
            rays = np.where(seen[..., None], xy[np.maximum(index, 0)], 0.0)
        else:  # no usable blob in this frame: every track misses it
            rays = np.zeros((*index.shape, 2))
        X, ray, kept = self.geom.triangulate(rays, seen, max_ray_px=self.ray_px)
        used = np.zeros(camera.size, dtype=bool)
        used[index[kept]] = True
        long_gap = tracks.missed >= self.keep_label_frames
        tracks.update(X, _rms(ray), kept.sum(axis=0))
        floor = -np.inf if self.floor_mm is None else self.floor_mm
        current = (tracks.missed == 0) & (tracks.position[:, 2] >= floor)
        crossed = crossed_rays(
            self.geom, tracks.position, current, index, kept, xy, self.gate_px, self.tol_mm
        )
        # After more than a short gap a track may have caught another marker's blobs:
        # its label is earned again, from the cluster fit or the links (checks of the
        # track by far partners with wide link ranges would let a wrong one pass).
        # Those are where a trajectory may have passed to another marker: a new number.
        tracks.renew((long_gap & (tracks.missed == 0)) | crossed)
        back = long_gap & (tracks.missed == 0) & (tracks.label >= 0)
        # A point two rays make, one of whose blobs another point explains, may be where no
        # marker is (:mod:`.crossed_rays`): no evidence for the label tracking carried.
        back |= crossed & (tracks.label >= 0)
        if self.floor_mm is not None:
            # A marker on the floor and its reflection are a few mm apart and their
            # tracks may trade blobs: whether a track is a reflection is where it is now.
            tracks.ghost = tracks.position[:, 2] < self.floor_mm
            back |= tracks.ghost & (tracks.label >= 0)
        tracks.label[back] = -1
        tracks.age[back] = 0
        self._new_tracks(xy, camera, usable & ~used & ~near, used)
        self._check_calibration(camera, usable, used)
        alive = tracks.missed <= self.bridge_frames
        # a copy of a labelled marker's point (its blobs split between two tracks) goes
        alive &= ~duplicate_tracks(
            tracks.position, (tracks.missed == 0) & ~tracks.ghost, tracks.label, self.apart_mm
        )
        tracks.keep(alive)
        # points of two rays another point's blob may have made take no label by links
        self._crossed = np.concatenate([crossed, np.zeros(alive.size - crossed.size, bool)])[alive]
        self._label()
        return self._result(flags)

    def current_points(self) -> FloatArray:
        """Points of the last frame (K, 3) mm that are not reflections, labelled or not,
        in the order :meth:`seed_labels` takes."""
        tracks = self.tracks
        return np.asarray(tracks.position[(tracks.missed == 0) & ~tracks.ghost])

    def seed_labels(self, marker_of: Any) -> int:
        """Give labels to the last frame's points from outside (a template fit).

        For a trial that starts in a known pose (a range-of-motion trial starting in the
        static pose): the labels are then carried by tracking and checked against the
        model every frame like any other (an inconsistent one is dropped).

        Parameters
        ----------
        marker_of : array_like of int, shape (K,)
            Marker (index into the model's labels) of each point of
            :meth:`current_points`, -1 to leave a point as it is.

        Returns
        -------
        int
            Points labelled.

        Raises
        ------
        ReconstructionError
            For a shape that differs from :meth:`current_points`'s, an unknown marker or
            a marker given twice.
        """
        tracks = self.tracks
        rows = np.flatnonzero((tracks.missed == 0) & ~tracks.ghost)
        marker = np.asarray(marker_of, dtype=np.intp)
        if marker.shape != rows.shape:
            raise ReconstructionError(f"marker_of must have shape {rows.shape}")
        give = marker >= 0
        if np.any(marker >= len(self.model.labels)) or np.unique(marker[give]).size < give.sum():
            raise ReconstructionError("marker_of names an unknown marker or one twice")
        tracks.label[np.isin(tracks.label, marker[give])] = -1
        tracks.label[rows[give]] = marker[give]
        tracks.age[rows[give]] = 0
        self._update_anchors()
        return int(give.sum())

    def _new_tracks(
        self, xy: FloatArray, camera: IntArray, free: NDArray[np.bool_], used: NDArray[np.bool_]
    ) -> None:
        """New tracks from blobs nothing explains; marks their blobs used."""
        idx = np.flatnonzero(free)
        if idx.size < self.min_cameras:
            return
        found = match_blobs(
            self.geom,
            xy[idx],
            camera[idx],
            gate_px=self.epipolar_px,
            min_cameras=self.min_cameras,
            max_ray_px=self.ray_px,
        )
        if found.points.shape[0] == 0:
            return
        blobs = found.blobs[found.blobs >= 0]
        used[idx[blobs]] = True
        ghost = (
            found.points[:, 2] < self.floor_mm
            if self.floor_mm is not None
            else np.zeros(found.points.shape[0], dtype=bool)
        )
        self.tracks.add(found.points, ghost, _rms(found.ray_px), found.n_cameras)

    def _label(self) -> None:
        tracks = self.tracks
        M = len(self.model.labels)
        seen = tracks.missed == 0
        labelled = np.flatnonzero((tracks.label >= 0) & seen)
        points = self._points
        points.fill(np.nan)
        points[tracks.label[labelled]] = tracks.position[labelled]
        age = np.zeros(M, dtype=np.intp)
        age[tracks.label[labelled]] = tracks.age[labelled]
        drop = inconsistent_labels(self.model, points, age, self.tol_mm)
        changed = bool(drop.any())  # labels other than those of ``points``
        if changed:
            bad = np.isin(tracks.label, np.flatnonzero(drop)) & seen
            tracks.label[bad] = -1
            tracks.age[bad] = 0
        candidates = seen & (tracks.label < 0) & ~tracks.ghost
        if candidates.any():
            current = seen & ~tracks.ghost
            rows = np.flatnonzero(current)
            labels = assign_labels(
                self.model,
                tracks.position[rows],
                tracks.label[rows].copy(),
                tol_mm=self.tol_mm,
                rms_mm=self.rms_mm,
                margin_mm=self.margin_mm,
                anchors=self._anchors,
                linkable=~self._crossed[rows],
                twins=self._twin_partners,
            )
            new = rows[(labels >= 0) & (tracks.label[rows] < 0)]
            if new.size:
                taken = labels[np.searchsorted(rows, new)]
                # A label taken by a new point ends the old (missed) track of that label.
                stale = np.isin(tracks.label, taken) & ~np.isin(np.arange(len(tracks)), new)
                tracks.label[new] = taken
                tracks.age[new] = 0
                tracks.label[stale] = -1
                changed = True
        if self._twins:  # refills the points buffer: changed again only if it drops
            changed = self._check_twins()
        if self.model.sides[0].size:
            self._check_handedness(refill=changed)
        if self._pairs:
            self._check_pairs()
        self._update_anchors()

    def _check_twins(self) -> bool:
        """Drop the labels of twin clusters a marker off them refutes by its links
        (:func:`.twin_clusters.refuted_twins`): found again next frame. True if any was."""
        tracks, points = self.tracks, self._points
        lab = (tracks.label >= 0) & (tracks.missed == 0)
        points.fill(np.nan)
        points[tracks.label[lab]] = tracks.position[lab]
        free = tracks.position[(tracks.missed == 0) & (tracks.label < 0) & ~tracks.ghost]
        drop = refuted_twins(self.model, self._twins, points, free, self.tol_mm)
        return self._unlabel(drop)

    def _check_handedness(self, refill: bool) -> None:
        """Drop the labels of flat clusters whose references say they are the wrong way
        round (a wrong identity passes every distance check): found again next frame.
        ``refill``: labels changed since :meth:`_label` filled the points buffer."""
        tracks = self.tracks
        points = self._points
        if refill:
            lab = (tracks.label >= 0) & (tracks.missed == 0)
            points.fill(np.nan)
            points[tracks.label[lab]] = tracks.position[lab]
        self._unlabel(misplaced_segments(self.model.segment_arrays, self.model.sides, points))

    def _check_pairs(self) -> None:
        """Exchange the labels of two link-only markers a cluster's references say are
        the wrong way round (:func:`.reference_pairs.exchanged_references`)."""
        tracks, points = self.tracks, self._points
        lab = (tracks.label >= 0) & (tracks.missed == 0)
        points.fill(np.nan)
        points[tracks.label[lab]] = tracks.position[lab]
        for m, n in exchanged_references(self.model, self._pairs, points):
            a, b = lab & (tracks.label == m), lab & (tracks.label == n)
            tracks.label[a], tracks.label[b] = n, m
            tracks.age[a | b] = 0  # a label newly held

    def _unlabel(self, drop: NDArray[np.bool_]) -> bool:
        """Unlabel the seen tracks of the markers ``drop`` (M,); True if any was."""
        if drop.any():
            bad = np.isin(self.tracks.label, np.flatnonzero(drop)) & (self.tracks.missed == 0)
            self.tracks.label[bad] = -1
            self.tracks.age[bad] = 0
        return bool(drop.any())

    def _update_anchors(self) -> None:
        tracks = self.tracks
        lab = np.flatnonzero((tracks.label >= 0) & (tracks.missed == 0))
        seg = self._segment_of[tracks.label[lab]]
        lab, seg = lab[seg >= 0], seg[seg >= 0]
        S = self._anchors.shape[0]
        n = np.bincount(seg, minlength=S)
        position = tracks.position[lab]
        total = np.stack(
            [np.bincount(seg, weights=position[:, axis], minlength=S) for axis in range(3)],
            axis=1,
        )
        with np.errstate(invalid="ignore", divide="ignore"):
            self._anchors = np.where((n > 0)[:, None], total / n[:, None], self._anchors)

    def _result(self, flags: IntArray) -> IdentifiedFrame:
        tracks = self.tracks
        M = len(self.model.labels)
        points = np.full((M, 3), np.nan)
        residual = np.full(M, np.nan)
        n_cam = np.zeros(M, dtype=np.intp)
        seen = tracks.missed == 0
        lab = np.flatnonzero((tracks.label >= 0) & seen)
        points[tracks.label[lab]] = tracks.position[lab]
        residual[tracks.label[lab]] = tracks.residual[lab]
        n_cam[tracks.label[lab]] = tracks.views[lab]
        trajectory = np.full(M, -1, dtype=np.intp)
        trajectory[tracks.label[lab]] = tracks.ident[lab]
        loose = np.flatnonzero(seen & (tracks.label < 0) & ~tracks.ghost)
        return IdentifiedFrame(
            points=points,
            residual_px=residual,
            n_cameras=n_cam,
            unlabelled=int(loose.size),
            ghosts=int((seen & tracks.ghost).sum()),
            camera_flags=flags.astype(np.intp),
            trajectory=trajectory,
            loose_points=tracks.position[loose],
            loose_trajectory=tracks.ident[loose],
            loose_residual_px=tracks.residual[loose],
        )


def _rms(ray_px: FloatArray) -> FloatArray:
    """RMS over the cameras (axis 0) of ray errors (C, K), NaN where none."""
    n = np.isfinite(ray_px).sum(axis=0)
    square = ray_px**2
    square[np.isnan(square)] = 0.0  # as np.nansum, without its overhead
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.asarray(np.sqrt(square.sum(axis=0) / n))
