"""Marker (LED) trajectories: generated motions and replay of real C3D recordings.

Every motion answers one vectorised question, :meth:`Motion.sample`: where was
marker ``markers[i]`` at time ``times[i]``? A time-multiplexed device samples
each LED at its own slot time, so positions are asked per (time, marker) pair.
World frame: mm, z up, floor at z = 0, the capture volume around (0, 0, 900).
NaN means the marker does not exist at that moment (missing in a C3D file);
the device reports it as not seen.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
import numpy.typing as npt

from spotlab.io import read_c3d
from spotlab.simulators.motion_base import F64, I64, Motion
from spotlab.simulators.walking_body import GAIT_LABELS, Gait, body_pose

__all__ = [
    "GAIT_LABELS", "MOTIONS", "CallableMotion", "Concat", "Delayed", "Gait", "Motion",
    "RigidClusters", "SampledMotion", "StaticMarkers", "Subset", "WandDance", "body_pose",
    "from_c3d", "make_motion", "reference_markers", "static_points",
]  # fmt: skip

MOTIONS = ("wand", "cluster", "gait", "lframe")


class CallableMotion(Motion):
    """Trajectories given by a function ``fn(times (K,)) -> positions (K, M, 3)`` in mm.

    Parameters
    ----------
    fn : callable
        Vectorised over times; NaN where a marker is missing.
    n_markers : int
        ``M``.
    labels : sequence of str, optional
        Marker labels.
    """

    def __init__(
        self,
        fn: Callable[[F64], npt.ArrayLike],
        n_markers: int,
        labels: Sequence[str] | None = None,
    ) -> None:
        self.fn = fn
        self.n_markers = n_markers
        self.labels = tuple(labels) if labels else tuple(f"M{i}" for i in range(n_markers))

    def sample(self, times: F64, markers: I64) -> F64:
        t = np.asarray(times, dtype=np.float64)
        pos = np.asarray(self.fn(t), dtype=np.float64).reshape(t.size, self.n_markers, 3)
        return np.asarray(pos[np.arange(t.size), np.asarray(markers, dtype=np.int64)])


class StaticMarkers(Motion):
    """Markers that do not move, e.g. an L-frame on the floor, shape (M, 3) mm."""

    def __init__(self, points: npt.ArrayLike, labels: Sequence[str] | None = None) -> None:
        self.points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        self.n_markers = self.points.shape[0]
        self.labels = tuple(labels) if labels else tuple(f"S{i}" for i in range(self.n_markers))

    def sample(self, times: F64, markers: I64) -> F64:
        return self.points[np.asarray(markers, dtype=np.int64)].copy()


def reference_markers(n: int, seed: int = 0) -> StaticMarkers:
    """``n`` static markers: an L-frame on the floor first, then points scattered in the volume.

    The L-frame's four markers sit 10 mm above the floor at (0, 0), (200, 0),
    (600, 0) and (0, 400) mm: the unequal spacing tells its axes apart.
    """
    lframe = np.array([[0, 0, 10], [200, 0, 10], [600, 0, 10], [0, 400, 10]], dtype=np.float64)
    labels = ["LF_O", "LF_X1", "LF_X2", "LF_Y"]
    pts = lframe[: min(n, 4)]
    if n > 4:
        rng = np.random.default_rng(np.random.SeedSequence([seed, 0x57A7]))
        extra = rng.uniform([-800, -800, 200], [800, 800, 1600], size=(n - 4, 3))
        pts = np.vstack([pts, extra])
        labels += [f"S{i}" for i in range(n - 4)]
    return StaticMarkers(pts, labels[:n])


class Concat(Motion):
    """Markers of several motions side by side: marker ids run through them in order."""

    def __init__(self, parts: Sequence[Motion]) -> None:
        self.parts = [p for p in parts if p.n_markers > 0]
        sizes = [p.n_markers for p in self.parts]
        self._starts = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        self.n_markers = int(self._starts[-1])
        self.labels = tuple(lab for p in self.parts for lab in p.labels)

    def sample(self, times: F64, markers: I64) -> F64:
        m = np.asarray(markers, dtype=np.int64)
        out = np.full((m.size, 3), np.nan)
        part = np.searchsorted(self._starts, m, side="right") - 1
        for j, p in enumerate(self.parts):
            rows = part == j
            if rows.any():
                out[rows] = p.sample(np.asarray(times)[rows], m[rows] - self._starts[j])
        return out


class Subset(Motion):
    """The first ``n`` markers of another motion."""

    def __init__(self, motion: Motion, n: int) -> None:
        self.motion = motion
        self.n_markers = min(n, motion.n_markers)
        self.labels = motion.labels[: self.n_markers]

    def sample(self, times: F64, markers: I64) -> F64:
        return self.motion.sample(times, markers)


class Delayed(Motion):
    """Another motion ``shift_s`` seconds later in its course: ``sample(t)`` is the
    motion's at ``t + shift_s`` (simulators powered up at different moments see one
    world when each shifts by its power-up time since a common scene epoch)."""

    def __init__(self, motion: Motion, shift_s: float) -> None:
        self.motion = motion
        self.shift_s = float(shift_s)
        self.n_markers = motion.n_markers
        self.labels = motion.labels

    def sample(self, times: F64, markers: I64) -> F64:
        return self.motion.sample(np.asarray(times, dtype=np.float64) + self.shift_s, markers)


class WandDance(Motion):
    """Two or three markers on a wand waved through the volume as an operator does.

    The operator walks slowly through the capture volume (a Lissajous path of
    ``walk`` mm amplitude, 0.05-0.09 Hz) while sweeping the wand with the arm, quickly
    (``reach`` mm sideways at 0.35-0.55 Hz) and from near the floor to above the head
    (``centre[2] +- extent_z``, 0.18-0.28 Hz), turning and tilting it so that it
    points in many directions. In 20 s the wand sweeps most of the volume the cameras
    look at. Marker 0 and 1 are the wand ends (``WAND_A``, ``WAND_B``, ``length`` mm
    apart); with ``middle_mm``, marker 2 (``WAND_M``) sits on the wand ``middle_mm``
    from end A, as on a passive three-marker wand.

    Parameters
    ----------
    length : float
        Distance between the ends (mm).
    centre : tuple of 3 floats
        Middle of the volume (mm).
    walk, reach, extent_z, radius : float
        The operator's path amplitude, the arm's sideways sweep, the wand's height
        sweep, and the circle the operator stays in (mm).
    seed : int
        Seed of the frequencies and phases.
    middle_mm : float, optional
        Distance of a third, middle marker from end A (mm), ``0 < middle_mm < length``.
    tempo : float
        How fast the operator waves: the motion at time ``t`` is the tempo-1 motion's
        at ``tempo * t``.
    """

    def __init__(
        self,
        length: float = 500.0,
        centre: tuple[float, float, float] = (0.0, 0.0, 1000.0),
        walk: float = 1100.0,
        reach: float = 500.0,
        extent_z: float = 700.0,
        radius: float = 1600.0,
        seed: int = 0,
        middle_mm: float | None = None,
        tempo: float = 1.0,
    ) -> None:
        rng = np.random.default_rng(np.random.SeedSequence([seed, 0x3A4D]))
        self.length = float(length)
        self.radius = float(radius)
        self.centre = np.asarray(centre, dtype=np.float64)
        self._amp = np.array([walk, walk, reach, reach, extent_z])
        self._freq = np.concatenate(
            [rng.uniform(0.05, 0.09, 2), rng.uniform(0.35, 0.55, 2), rng.uniform(0.18, 0.28, 1)]
        )  # Hz: walk x, y; arm x, y; arm up and down
        self._phase = rng.uniform(0, 2 * np.pi, size=5)
        self._yaw_rate = rng.uniform(0.5, 0.9) * rng.choice([-1.0, 1.0])  # rad/s
        self._tilt = (rng.uniform(0.2, 0.4), rng.uniform(0, 2 * np.pi))  # Hz, phase
        if middle_mm is not None and not 0.0 < middle_mm < self.length:
            raise ValueError(f"the middle marker must lie between the ends, got {middle_mm} mm")
        self.tempo = float(tempo)
        # Position of each marker along the wand from its centre, in lengths.
        self._along = np.array(
            [-0.5, 0.5] + ([] if middle_mm is None else [-0.5 + middle_mm / length])
        )
        self.n_markers = self._along.size
        self.labels = ("WAND_A", "WAND_B", "WAND_M")[: self.n_markers]

    def sample(self, times: F64, markers: I64) -> F64:
        t = self.tempo * np.asarray(times, dtype=np.float64)
        wave = self._amp * np.sin(2 * np.pi * self._freq * t[:, None] + self._phase)
        xy = np.stack([wave[:, 0] + wave[:, 2], wave[:, 1] + wave[:, 3]], axis=1)
        # The operator keeps inside a circle of radius ``radius``, as the floor space
        # between the cameras allows (soft limit: smooth, never beyond it).
        r = np.linalg.norm(xy, axis=1, keepdims=True)
        with np.errstate(invalid="ignore", divide="ignore"):
            xy = np.where(r > 0, xy * (self.radius * np.tanh(r / self.radius) / r), xy)
        c = self.centre + np.column_stack([xy, wave[:, 4]])
        yaw = self._yaw_rate * t + 0.5 * np.sin(0.31 * t)
        pitch = 0.7 * np.sin(2 * np.pi * self._tilt[0] * t + self._tilt[1])
        d = np.stack([np.cos(pitch) * np.cos(yaw), np.cos(pitch) * np.sin(yaw), np.sin(pitch)], 1)
        along = self._along[np.asarray(markers, dtype=np.int64)][:, None]
        return np.asarray(c + along * self.length * d)


def _rotations(axis: F64, angle: F64) -> F64:
    """Rodrigues: unit axes (K, 3) and angles (K,) rad -> rotation matrices (K, 3, 3)."""
    k = axis / np.linalg.norm(axis, axis=1, keepdims=True)
    K = np.zeros((k.shape[0], 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -k[:, 2], k[:, 1], -k[:, 0]
    K[:, 1, 0], K[:, 2, 0], K[:, 2, 1] = k[:, 2], -k[:, 1], k[:, 0]
    s, c = np.sin(angle)[:, None, None], np.cos(angle)[:, None, None]
    return np.eye(3) + s * K + (1 - c) * (K @ K)


class RigidClusters(Motion):
    """Rigid clusters of ``cluster_size`` markers, each translating and rotating on its own.

    Cluster ``j`` holds markers ``j * cluster_size ...``; its shape is a fixed,
    asymmetric set of points within about 100 mm; its centre loops through
    the volume and it turns about a slowly precessing axis.
    """

    def __init__(self, n_markers: int = 8, cluster_size: int = 4, seed: int = 0) -> None:
        if cluster_size < 3:
            raise ValueError("a rigid cluster needs at least 3 markers")
        rng = np.random.default_rng(np.random.SeedSequence([seed, 0xC1A5]))
        self.cluster_size = cluster_size
        self.n_markers = n_markers
        n_clusters = -(-n_markers // cluster_size)
        base = np.array([[0, 0, 0], [80, 0, 0], [0, 60, 0], [30, 30, 45]], dtype=np.float64)
        if cluster_size > 4:
            base = np.vstack([base, rng.uniform(-50, 50, size=(cluster_size - 4, 3))])
        self.shape = (base[:cluster_size] - base[:cluster_size].mean(0)).copy()
        self._freq = rng.uniform(0.05, 0.2, size=(n_clusters, 3))
        self._phase = rng.uniform(0, 2 * np.pi, size=(n_clusters, 3))
        self._spin = rng.uniform(0.4, 1.5, size=n_clusters) * rng.choice([-1, 1], n_clusters)
        self._axis = rng.normal(size=(n_clusters, 3))
        self.labels = tuple(f"C{i // cluster_size}_{i % cluster_size}" for i in range(n_markers))

    def sample(self, times: F64, markers: I64) -> F64:
        t = np.asarray(times, dtype=np.float64)
        m = np.asarray(markers, dtype=np.int64)
        j, local = m // self.cluster_size, m % self.cluster_size
        amp = np.array([700.0, 700.0, 400.0])
        centre = np.array([0.0, 0.0, 1000.0]) + amp * np.sin(
            2 * np.pi * self._freq[j] * t[:, None] + self._phase[j]
        )
        axis = self._axis[j] + 0.5 * np.stack([np.sin(0.2 * t), np.cos(0.17 * t), 0 * t], 1)
        R = _rotations(axis, self._spin[j] * t)
        return np.asarray(centre + np.einsum("kij,kj->ki", R, self.shape[local]))


class SampledMotion(Motion):
    """Trajectories sampled at increasing times, linearly interpolated.

    Parameters
    ----------
    times : array_like, shape (F,)
        Sample times in seconds, increasing.
    positions : array_like, shape (F, M, 3)
        Positions in mm; NaN where the marker is missing.
    loop : bool
        Repeat the recording after its end (otherwise every marker is missing after it).
    labels : sequence of str, optional
        Marker labels.

    Notes
    -----
    A position between two samples is NaN when either sample is missing, so a
    gap in the recording becomes an occlusion.
    """

    def __init__(
        self,
        times: npt.ArrayLike,
        positions: npt.ArrayLike,
        loop: bool = True,
        labels: Sequence[str] | None = None,
    ) -> None:
        self.times = np.asarray(times, dtype=np.float64)
        self.data = np.asarray(positions, dtype=np.float64)
        if self.data.ndim != 3 or self.data.shape[2] != 3 or self.data.shape[0] != self.times.size:
            raise ValueError("positions must have shape (F, M, 3) with F = len(times)")
        if self.times.size < 2 or np.any(np.diff(self.times) <= 0):
            raise ValueError("a sampled motion needs at least 2 strictly increasing times")
        self.loop = loop
        self.n_markers = self.data.shape[1]
        self.labels = tuple(labels) if labels else tuple(f"M{i}" for i in range(self.n_markers))
        self._dt = float(self.times[-1] - self.times[-2])
        self.duration = float(self.times[-1] - self.times[0]) + self._dt

    def sample(self, times: F64, markers: I64) -> F64:
        rel = self.times - self.times[0]
        n = rel.size
        t = np.asarray(times, dtype=np.float64) - self.times[0]
        m = np.asarray(markers, dtype=np.int64)
        if self.loop:
            t = np.mod(t, self.duration)
        i = np.searchsorted(rel, t, side="right") - 1
        inside = (i >= 0) & (t < self.duration)
        i = np.clip(i, 0, n - 1)
        j = (i + 1) % n if self.loop else np.minimum(i + 1, n - 1)
        seg_end = np.where(i + 1 < n, rel[np.minimum(i + 1, n - 1)], self.duration)
        frac = np.where(j == i, 0.0, (t - rel[i]) / (seg_end - rel[i]))
        p0, p1 = self.data[i, m], self.data[j, m]
        out = np.where(frac[:, None] > 0, p0 + frac[:, None] * (p1 - p0), p0)
        out[~inside] = np.nan
        return np.asarray(out)


def from_c3d(path: str | Path, *, center: bool = True, loop: bool = True) -> SampledMotion:
    """The 3-D markers of a C3D file as a motion (needs the ``c3d`` package).

    Parameters
    ----------
    path : str or Path
        The C3D file.
    center : bool
        Shift the recording horizontally so that its mean marker position is
        above the origin (the simulated rig looks at the origin).
    loop : bool
        Repeat the recording after its end.

    Returns
    -------
    SampledMotion
        Positions in mm (``POINT:UNITS`` of m or cm are converted), missing
        samples (negative residual) as NaN.

    Raises
    ------
    ValueError
        If the file holds no 3-D points.
    spotlab.io.FileFormatError
        If the file cannot be read as C3D (the message names the file and the cause).
    """
    trial = read_c3d(path)
    if trial.n_frames == 0 or trial.n_markers == 0:
        raise ValueError(f"{path}: no 3-D points in this C3D file")
    if trial.units != "mm":
        raise ValueError(f"{path}: points in {trial.units!r}, a unit that cannot be converted")
    rate, labels, xyz = trial.point_rate, trial.labels, trial.points.copy()
    if center and np.isfinite(xyz).any():
        xyz[..., :2] -= np.nanmean(xyz[..., :2].reshape(-1, 2), axis=0)
    times = np.arange(xyz.shape[0]) / rate
    n = xyz.shape[1]
    return SampledMotion(times, xyz, loop=loop, labels=(labels + [""] * n)[:n])


def make_motion(name: str | Path, n_markers: int, seed: int = 0) -> Motion:
    """The motion the command line names, with exactly ``n_markers`` markers.

    ``wand``: the two wand LEDs, then reference markers (an L-frame first);
    ``cluster``: rigid clusters of 4; ``gait``: the 19 walking-body markers;
    ``lframe``: static reference markers only (the L-frame first, as a static
    recording of a calibration's reference object sees it); anything else: a C3D
    file. Motions with too few markers are padded with static reference markers,
    those with too many are cut.
    """
    if name == "wand":
        base: Motion = WandDance(seed=seed)
    elif name == "cluster":
        base = RigidClusters(n_markers=n_markers, seed=seed)
    elif name == "gait":
        base = Gait()
    elif name == "lframe":
        return reference_markers(n_markers, seed)
    else:
        base = from_c3d(Path(name))
    if base.n_markers >= n_markers:
        return base if base.n_markers == n_markers else Subset(base, n_markers)
    return Concat([base, reference_markers(n_markers - base.n_markers, seed)])


def static_points(motion: Motion) -> list[tuple[int, str, F64]]:
    """The static markers of a motion with their known coordinates.

    Parameters
    ----------
    motion : Motion
        As :func:`make_motion` builds it.

    Returns
    -------
    list of (int, str, ndarray)
        Marker index (0-based, the LED id), label and position (3,) in mm, for every
        marker that stands still (the L-frame and the other reference markers), in
        marker order. Empty when the motion has none.
    """
    if isinstance(motion, StaticMarkers):
        return [(i, motion.labels[i], motion.points[i]) for i in range(motion.n_markers)]
    if isinstance(motion, Concat):
        out = []
        for start, part in zip(motion._starts, motion.parts, strict=False):
            out += [(int(start) + i, lab, p) for i, lab, p in static_points(part)]
        return out
    if isinstance(motion, Subset):
        return [item for item in static_points(motion.motion) if item[0] < motion.n_markers]
    return []
