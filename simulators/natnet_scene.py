"""What the simulated OptiTrack system sees: the walking body's labelled markers.

The scene is the centroid simulator's walking body (:class:`GaitBody`, seed = the
subject), its first ``M`` markers labelled with the body's names; the pelvis
markers (``LASI``, ``RASI``, ``LPSI``, ``RPSI``) form the rigid body ``pelvis``,
its pose fitted to them in every frame. A NatNet server reports already
reconstructed 3-D markers, so no camera is simulated: the ``C`` cameras are only
named and placed on a ring in the model descriptions.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from spotlab.simulators.centroid_body import BODY_LABELS, GaitBody
from spotlab.simulators.natnet_wire import CameraDescription, RigidBodyDescription, RigidBodyPose

F64 = npt.NDArray[np.float64]

PELVIS = ("LASI", "RASI", "LPSI", "RPSI")
PELVIS_ID = 1
#: Model id of the marker set's labelled markers (docs/protocols/natnet.md §5).
MODEL_ID = 1


def quaternion(r: F64) -> tuple[float, float, float, float]:
    """Unit quaternion (x, y, z, w) of a rotation matrix (3, 3)."""
    w = math.sqrt(max(0.0, 1.0 + r[0, 0] + r[1, 1] + r[2, 2])) / 2
    x = math.sqrt(max(0.0, 1.0 + r[0, 0] - r[1, 1] - r[2, 2])) / 2
    y = math.sqrt(max(0.0, 1.0 - r[0, 0] + r[1, 1] - r[2, 2])) / 2
    z = math.sqrt(max(0.0, 1.0 - r[0, 0] - r[1, 1] + r[2, 2])) / 2
    x = math.copysign(x, r[2, 1] - r[1, 2])
    y = math.copysign(y, r[0, 2] - r[2, 0])
    z = math.copysign(z, r[1, 0] - r[0, 1])
    return x, y, z, w


class NatNetScene:
    """Labelled markers (mm) and the pelvis rigid body at any frame.

    Parameters
    ----------
    markers : int
        Markers of the body streamed, 1-40 (its first ``markers`` labels).
    cameras : int
        Cameras named in the model descriptions.
    rate_hz : float
        Frame rate; frame ``k`` is taken at ``k / rate_hz`` s.
    seed : int
        The subject (0: the nominal body).
    """

    def __init__(self, markers: int = 40, cameras: int = 8, rate_hz: float = 100.0, seed: int = 0):
        if not 1 <= markers <= len(BODY_LABELS):
            raise ValueError(f"markers must be 1 to {len(BODY_LABELS)}, got {markers}")
        if not 1 <= cameras <= 64:
            raise ValueError(f"cameras must be 1 to 64, got {cameras}")
        if not 0 < rate_hz <= 1000:
            raise ValueError(f"the rate must be above 0 and at most 1000 Hz, got {rate_hz}")
        self.n_markers = markers
        self.n_cameras = cameras
        self.rate_hz = float(rate_hz)
        self.body = GaitBody.for_seed(seed)
        self.labels: tuple[str, ...] = tuple(BODY_LABELS[:markers])
        self.pelvis = [self.labels.index(n) for n in PELVIS if n in self.labels]
        first = self.markers_mm(np.zeros(1))[0]
        self._pelvis_ref = (
            first[self.pelvis] - first[self.pelvis].mean(axis=0) if len(self.pelvis) >= 3 else None
        )

    def time_s(self, frames: npt.ArrayLike) -> F64:
        """Scene time (s) of frame numbers (K,)."""
        return np.asarray(frames, dtype=np.float64) / self.rate_hz

    def markers_mm(self, t: F64) -> F64:
        """Markers at times (K,) s -> (K, M, 3) mm."""
        return np.asarray(self.body.all_markers(np.atleast_1d(t))[:, : self.n_markers])

    def rigid_bodies(self) -> list[RigidBodyDescription]:
        """The pelvis (when at least 3 of its markers are streamed) in the model descriptions."""
        if self._pelvis_ref is None:
            return []
        names = tuple(self.labels[i] for i in self.pelvis)
        return [RigidBodyDescription("pelvis", PELVIS_ID, self._pelvis_ref / 1000.0, names)]

    def poses(self, x_mm: F64) -> list[RigidBodyPose]:
        """The pelvis pose fitted (least squares) to the markers (M, 3) mm of one frame."""
        if self._pelvis_ref is None:
            return []
        p = x_mm[self.pelvis]
        c = p.mean(axis=0)
        u, _, vt = np.linalg.svd((p - c).T @ self._pelvis_ref)
        d = np.sign(np.linalg.det(u @ vt))
        r = u @ np.diag([1.0, 1.0, d]) @ vt
        err = float(np.linalg.norm(p - c - self._pelvis_ref @ r.T, axis=1).mean())
        pos = (float(c[0] / 1000), float(c[1] / 1000), float(c[2] / 1000))
        return [RigidBodyPose(PELVIS_ID, pos, quaternion(r), err / 1000.0)]

    def cameras(self) -> list[CameraDescription]:
        """``cam1..camC`` on a 4 m ring, 2.5 m up, each turned towards the middle."""
        out = []
        for k in range(self.n_cameras):
            a = 2 * math.pi * k / self.n_cameras
            yaw = a + math.pi
            out.append(
                CameraDescription(
                    f"cam{k + 1}",
                    (4.0 * math.cos(a), 4.0 * math.sin(a), 2.5),
                    (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)),
                )
            )
        return out
