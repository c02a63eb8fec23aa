"""A 40-marker walking body on 13 rigid segments, for identification tests and benchmarks.

The pelvis walks on a circle of ``radius`` mm around the volume centre like
:class:`spotlab.simulators.motions.Gait`; the trunk, head, thighs, shanks, feet, upper
arms and forearms follow sagittal joint angles of the gait phase. Each segment carries a
rigid cluster of 3 or 4 markers whose layout is scalene and differs left from right
(as in lab practice, so that a cluster and its mirror image cannot be confused).
World frame: mm, z up, floor at z = 0.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["SEGMENTS", "WalkingBody"]

FloatArray = NDArray[np.float64]

#: Segment -> (parent, joint position in the parent frame (mm), markers and their
#: positions in the segment frame (mm)); frames: x forward, y left, z up.
SEGMENTS: dict[str, tuple[str | None, tuple[float, ...], dict[str, tuple[float, ...]]]] = {
    "pelvis": (None, (0, 0, 0), {
        "LASI": (110, 120, 10), "RASI": (110, -125, 0), "LPSI": (-90, 55, 30),
        "RPSI": (-95, -45, 40)}),
    "trunk": ("pelvis", (0, 0, 80), {
        "C7": (-70, 0, 440), "CLAV": (70, 10, 380), "STRN": (95, -5, 210)}),
    "head": ("trunk", (0, 0, 500), {
        "LFHD": (90, 60, 130), "RFHD": (95, -55, 120), "BHD": (-80, 10, 150)}),
    "lthigh": ("pelvis", (0, 90, -70), {
        "LGTR": (0, 60, -60), "LTHI": (30, 75, -230), "LKNE": (0, 60, -420)}),
    "rthigh": ("pelvis", (0, -90, -70), {
        "RGTR": (-10, -60, -70), "RTHI": (40, -75, -300), "RKNE": (0, -60, -420)}),
    "lshank": ("lthigh", (0, 0, -430), {
        "LTTU": (45, 10, -60), "LTIB": (25, 70, -190), "LANK": (0, 55, -410)}),
    "rshank": ("rthigh", (0, 0, -430), {
        "RTTU": (45, -10, -70), "RTIB": (30, -70, -260), "RANK": (0, -55, -410)}),
    "lfoot": ("lshank", (0, 0, -420), {
        "LHEE": (-60, 5, -40), "LTOE": (150, 0, -40), "LMT5": (90, 45, -45)}),
    "rfoot": ("rshank", (0, 0, -420), {
        "RHEE": (-60, -5, -40), "RTOE": (150, 0, -40), "RMT5": (70, -45, -45)}),
    "luarm": ("trunk", (0, 180, 440), {
        "LSHO": (0, 20, 30), "LUPA": (-40, 30, -150), "LELB": (0, 35, -290)}),
    "ruarm": ("trunk", (0, -180, 440), {
        "RSHO": (0, -20, 30), "RUPA": (-45, -30, -110), "RELB": (0, -35, -290)}),
    "lfarm": ("luarm", (0, 0, -300), {
        "LFRM": (-30, 30, -120), "LWRA": (25, 20, -250), "LWRB": (-25, 25, -255)}),
    "rfarm": ("ruarm", (0, 0, -300), {
        "RFRM": (-30, -30, -160), "RWRA": (25, -20, -250), "RWRB": (-25, -25, -255)}),
}  # fmt: skip


def _rot(axis: int, angle: FloatArray) -> FloatArray:
    """Rotations (F, 3, 3) about a body axis (0 x, 1 y, 2 z) by ``angle`` (F,) rad."""
    c, s = np.cos(angle), np.sin(angle)
    R = np.zeros((angle.size, 3, 3))
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    R[:, axis, axis] = 1.0
    R[:, i, i], R[:, j, j], R[:, i, j], R[:, j, i] = c, c, -s, s
    return R


@dataclass(frozen=True)
class WalkingBody:
    """The walking body.

    Parameters
    ----------
    speed_mm_s : float
        Walking speed along the circle.
    radius_mm : float
        Radius of the walked circle around (0, 0).
    stride_hz : float
        Strides per second.
    """

    speed_mm_s: float = 1200.0
    radius_mm: float = 1200.0
    stride_hz: float = 0.9

    @property
    def labels(self) -> tuple[str, ...]:
        """Marker labels, segment by segment (40)."""
        return tuple(name for _, _, markers in SEGMENTS.values() for name in markers)

    @property
    def segments(self) -> dict[str, tuple[str, ...]]:
        """Segment name -> its marker labels."""
        return {seg: tuple(markers) for seg, (_, _, markers) in SEGMENTS.items()}

    def _joint_angles(self, ph: FloatArray) -> dict[str, FloatArray]:
        """Flexion angle (rad) of each segment relative to its parent, by gait phase."""
        out: dict[str, FloatArray] = {"trunk": 0.05 * np.sin(2 * ph), "head": 0.1 * np.sin(ph)}
        for side, p in (("l", ph), ("r", ph + np.pi)):
            out[side + "thigh"] = 0.4 * np.sin(p)
            out[side + "shank"] = -0.55 * (1 - np.cos(p + 0.6)) / 2
            out[side + "foot"] = 0.25 * np.sin(p - 0.4)
            out[side + "uarm"] = -0.35 * np.sin(p)
            out[side + "farm"] = 0.3 + 0.25 * (1 - np.cos(p)) / 2
        return out

    def poses(self, times: FloatArray) -> dict[str, tuple[FloatArray, FloatArray]]:
        """World pose ``(R (F, 3, 3), t (F, 3) mm)`` of every segment at ``times`` (F,) s."""
        t = np.asarray(times, dtype=np.float64)
        a = self.speed_mm_s * t / self.radius_mm
        ph = 2 * np.pi * self.stride_hz * t
        heading = a + np.pi / 2 + 0.06 * np.sin(ph)  # x forward along the circle
        R_pelvis = _rot(2, heading) @ _rot(0, 0.04 * np.sin(ph)) @ _rot(1, np.full(t.size, 0.05))
        pelvis = np.stack(
            [self.radius_mm * np.cos(a), self.radius_mm * np.sin(a), 1000 + 15 * np.cos(2 * ph)],
            axis=1,
        )
        angles = self._joint_angles(ph)
        poses: dict[str, tuple[FloatArray, FloatArray]] = {"pelvis": (R_pelvis, pelvis)}
        for seg, (parent, joint, _) in SEGMENTS.items():
            if parent is None:
                continue
            R_p, t_p = poses[parent]
            R = R_p @ _rot(1, -angles[seg])
            poses[seg] = (R, t_p + R_p @ np.asarray(joint, dtype=np.float64))
        return poses

    def markers(self, times: FloatArray) -> FloatArray:
        """Marker positions (F, 40, 3) mm at ``times`` (F,) s, in :attr:`labels` order."""
        poses = self.poses(times)
        parts = []
        for seg, (_, _, markers) in SEGMENTS.items():
            R, t = poses[seg]
            local = np.array(list(markers.values()), dtype=np.float64)
            parts.append(np.einsum("fij,mj->fmi", R, local) + t[:, None, :])
        return np.concatenate(parts, axis=1)

    def outward(self, times: FloatArray) -> FloatArray:
        """Unit normals (F, 40, 3) pointing from each segment's axis out through its markers."""
        poses = self.poses(times)
        parts = []
        for seg, (_, _, markers) in SEGMENTS.items():
            R, _ = poses[seg]
            local = np.array(list(markers.values()), dtype=np.float64)
            local[:, 2] = 0.0  # horizontal in the segment: away from its long axis
            local /= np.linalg.norm(local, axis=1, keepdims=True)
            parts.append(np.einsum("fij,mj->fmi", R, local))
        return np.concatenate(parts, axis=1)
