"""The walking body of the simulators: 19 surface markers on a sagittal-plane model.

:func:`body_pose` places the markers for given joint angles (the range-of-motion and
static poses use it too); :class:`Gait` walks it on a circle. World frame: mm, z up.
"""

from __future__ import annotations

import numpy as np

from spotlab.simulators.motion_base import F64, I64, Motion

__all__ = ["GAIT_LABELS", "WALKING_PELVIS_MM", "Gait", "body_pose"]

GAIT_LABELS = (
    "HEAD", "C7", "LSHO", "RSHO", "LELB", "RELB", "LWRA", "RWRA", "LASI", "RASI",
    "SACR", "LKNE", "RKNE", "LANK", "RANK", "LHEE", "RHEE", "LTOE", "RTOE",
)  # fmt: skip


def _abduct(f: F64, lat: float, lt: float, u: F64, top: F64, ab: F64) -> tuple[F64, F64, F64]:
    """A limb point (forward f, lateral ``lat * lt``, up u) turned outwards by ``ab``
    (rad) about the forward axis through the limb's top at height ``top``."""
    rel = u - top
    return f, lat * (lt - rel * np.sin(ab)), top + rel * np.cos(ab)


def body_pose(
    base: F64, fwd: F64, pel_z: F64, hip: F64, knee: F64, foot: F64, arm: F64,
    *, elbow: F64 | float = 0.3, hip_abd: F64 | float = 0.0, arm_abd: F64 | float = 0.0,
) -> F64:  # fmt: skip
    """The 19 markers of :class:`Gait`'s body in a pose -> (K, 19, 3) mm.

    Parameters
    ----------
    base : ndarray, shape (K, 2)
        Floor point below the pelvis (mm).
    fwd : ndarray, shape (K, 2)
        Unit heading on the floor.
    pel_z : ndarray, shape (K,)
        Pelvis height (mm).
    hip, knee, foot, arm : ndarray, shape (K, 2)
        Left and right joint angles (rad): hip flexion, knee flexion, foot pitch (toe
        down), shoulder flexion (arm forward).
    elbow, hip_abd, arm_abd : ndarray, shape (K, 2), or float
        Forearm flexion relative to the upper arm, hip and shoulder abduction (rad).
    """
    left = np.stack([-fwd[:, 1], fwd[:, 0]], 1)
    zero = np.zeros(base.shape[0])
    elbow, hip_abd, arm_abd = (np.broadcast_to(np.asarray(v, np.float64), hip.shape)
                               for v in (elbow, hip_abd, arm_abd))  # fmt: skip
    cols: dict[str, tuple[F64, F64, F64]] = {}  # (forward, left, up) in mm
    for k, (side, lat) in enumerate((("L", 1.0), ("R", -1.0))):
        h, kn, ft, ar = hip[:, k], knee[:, k], foot[:, k], arm[:, k]
        hip_u, sh_u = pel_z - 80, pel_z + 480

        kf, ku = 450 * np.sin(h), hip_u - 450 * np.cos(h)
        shank = h - kn
        af, au = kf + 430 * np.sin(shank), ku - 430 * np.cos(shank)
        ab = hip_abd[:, k]
        cols[side + "KNE"] = _abduct(kf, lat, 95, ku, hip_u, ab)
        cols[side + "ANK"] = _abduct(af, lat, 90, au, hip_u, ab)
        cols[side + "HEE"] = _abduct(
            af - 50 * np.cos(ft), lat, 90, au - 40 + 50 * np.sin(ft), hip_u, ab
        )
        cols[side + "TOE"] = _abduct(
            af + 140 * np.cos(ft), lat, 85, au - 50 - 140 * np.sin(ft), hip_u, ab
        )
        ef, eu = 300 * np.sin(ar), sh_u - 300 * np.cos(ar)
        fa = ar + elbow[:, k]
        ab = arm_abd[:, k]
        cols[side + "SHO"] = (zero, lat * 180 + zero, sh_u)
        cols[side + "ELB"] = _abduct(ef, lat, 200, eu, sh_u, ab)
        cols[side + "WRA"] = _abduct(
            ef + 260 * np.sin(fa), lat, 190, eu - 260 * np.cos(fa), sh_u, ab
        )
        cols[side + "ASI"] = (100 + zero, lat * 120 + zero, pel_z)
    cols["SACR"] = (-100 + zero, zero, pel_z + 10)
    cols["C7"] = (-40 + zero, zero, pel_z + 520)
    cols["HEAD"] = (60 + zero, zero, pel_z + 730)
    f = np.stack([cols[k][0] for k in GAIT_LABELS], 1)
    lft = np.stack([cols[k][1] for k in GAIT_LABELS], 1)
    up = np.maximum(np.stack([cols[k][2] for k in GAIT_LABELS], 1), 5.0)
    xy = base[:, None, :] + f[..., None] * fwd[:, None, :] + lft[..., None] * left[:, None, :]
    return np.concatenate([xy, up[..., None]], axis=2)


#: Mean pelvis height of the walk (mm): the straight stance leg (hip 80 mm below the
#: pelvis, thigh 450, shank 430) then leaves the ankle marker 55-85 mm above the floor
#: and the heel and toe markers 10 mm or more; 70 mm lower, they went through it.
WALKING_PELVIS_MM = 1020.0


class Gait(Motion):
    """A body walking on a circle of ``radius`` mm at ``speed`` m/s, with 19 surface markers.

    A sagittal-plane model: hip, knee and arm angles follow the gait phase, the
    pelvis bobs twice per stride, left and right are half a stride apart. Labels
    are Plug-in-Gait-like (``GAIT_LABELS``).
    """

    def __init__(self, speed: float = 1.2, radius: float = 1200.0, stride_hz: float = 0.9) -> None:
        self.speed = speed * 1000.0
        self.radius = radius
        self.stride_hz = stride_hz
        self.n_markers = len(GAIT_LABELS)
        self.labels = GAIT_LABELS

    def _all(self, t: F64) -> F64:
        """All 19 markers at times (K,) -> (K, 19, 3) mm."""
        a = self.speed * t / self.radius
        base = np.stack([self.radius * np.cos(a), self.radius * np.sin(a)], 1)
        fwd = np.stack([-np.sin(a), np.cos(a)], 1)
        ph = 2 * np.pi * self.stride_hz * t
        p = np.stack([ph, ph + np.pi], 1)  # (K, 2): left, right
        hip = 0.4 * np.sin(p)
        knee = 0.55 * (1 - np.cos(p + 0.6)) / 2
        return body_pose(
            base, fwd, WALKING_PELVIS_MM + 15.0 * np.cos(2 * ph), hip, knee, 0.5 * (hip - knee),
            -0.35 * np.sin(p),
        )  # fmt: skip

    def sample(self, times: F64, markers: I64) -> F64:
        t = np.asarray(times, dtype=np.float64)
        return np.asarray(self._all(t)[np.arange(t.size), np.asarray(markers, dtype=np.int64)])
