"""The simulated world: LED trajectories, PSD cameras, mirrors, ambient light, occluders.

Lengths are mm, times are scene seconds (the device maps its world clock to
scene time), detector coordinates are counts 0-4094 with 2048 on the optical
axis. Cameras follow the project convention ``x_cam = R @ X + t``, looking along
their +z axis with +x to the right and +y down the detector.

The scene only does geometry: where each LED and each mirror image of it lands
on each detector, how far the light travels, at which angle to the optical axis
it arrives, and whether something is in the way. Turning that into power and a
detector reading is :mod:`spotlab.simulators.psd`'s job.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from spotlab.simulators.motions import Motion

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]
B = npt.NDArray[np.bool_]

DETECTOR_CENTRE = 2048.0
DETECTOR_MAX = 4094.0


@dataclass(frozen=True)
class PsdCamera:
    """A lateral-photodiode camera: a lens in front of a dual-axis PSD.

    Parameters
    ----------
    R : array_like, shape (3, 3)
        World-to-camera rotation.
    t : array_like, shape (3,)
        World-to-camera translation in mm (``x_cam = R @ X + t``).
    focal : float
        Focal length in detector counts.
    principal : tuple of float
        Principal point in counts, default (2048, 2048).
    k1, k2 : float
        Radial lens distortion on normalised coordinates,
        ``x_d = x_n (1 + k1 r^2 + k2 r^4)``.
    name : str
        Label.
    """

    R: F64
    t: F64
    focal: float = 3500.0
    principal: tuple[float, float] = (DETECTOR_CENTRE, DETECTOR_CENTRE)
    k1: float = 0.0
    k2: float = 0.0
    name: str = ""

    def __post_init__(self) -> None:
        object.__setattr__(self, "R", np.asarray(self.R, dtype=np.float64).reshape(3, 3))
        object.__setattr__(self, "t", np.asarray(self.t, dtype=np.float64).reshape(3))

    @property
    def center(self) -> F64:
        """Projection centre in world mm, shape (3,)."""
        return np.asarray(-self.R.T @ self.t)

    @classmethod
    def look_at(
        cls,
        eye: npt.ArrayLike,
        target: npt.ArrayLike,
        up: npt.ArrayLike = (0.0, 0.0, 1.0),
        focal: float = 3500.0,
        name: str = "",
        k1: float = 0.0,
    ) -> PsdCamera:
        """A camera at ``eye`` (mm) whose optical axis points at ``target`` (mm)."""
        e = np.asarray(eye, dtype=np.float64)
        z = np.asarray(target, dtype=np.float64) - e
        z /= np.linalg.norm(z)
        x = np.cross(z, np.asarray(up, dtype=np.float64))
        if np.linalg.norm(x) < 1e-9:
            raise ValueError("camera 'up' direction is parallel to its optical axis")
        x /= np.linalg.norm(x)
        y = np.cross(z, x)
        R = np.stack([x, y, z])
        return cls(R=R, t=-R @ e, focal=focal, name=name, k1=k1)


@dataclass(frozen=True)
class Mirror:
    """An infinite reflecting plane (a shiny floor, a window, a table top).

    Light from an LED on the normal side reaches a camera on the same side as
    if it came from the LED's mirror image, weakened by ``reflectance``.
    """

    point: tuple[float, float, float] = (0.0, 0.0, 0.0)
    normal: tuple[float, float, float] = (0.0, 0.0, 1.0)
    reflectance: float = 0.05


@dataclass(frozen=True)
class SphereOccluder:
    """A static opaque sphere (a body, a column) of ``radius`` mm at ``center`` mm."""

    center: tuple[float, float, float]
    radius: float


@dataclass(frozen=True)
class OcclusionInterval:
    """LED ``led`` is hidden from camera ``camera`` (``None``: all) for scene time [t0, t1) s."""

    led: int
    t0: float
    t1: float
    camera: int | None = None


@dataclass(frozen=True)
class Ambient:
    """Ambient infrared light reaching each detector.

    Parameters
    ----------
    level : float or sequence of float
        Mean ambient power per camera, in intensity units (the scale of the
        ``intensity`` field), before background differencing.
    flicker : float
        Relative modulation depth of mains flicker (0-1).
    flicker_hz : float
        Flicker frequency (twice the mains frequency).
    centroid : tuple of float
        Where the ambient light's centroid falls on every detector, counts.
    """

    level: float | Sequence[float] = 0.0
    flicker: float = 0.2
    flicker_hz: float = 100.0
    centroid: tuple[float, float] = (DETECTOR_CENTRE, DETECTOR_CENTRE)


@dataclass
class Spots:
    """Where the light of each LED lands: arrays of shape (N, C, S).

    S = 1 + number of mirrors: spot 0 is the direct image, spot 1+j the image in mirror j.

    Attributes
    ----------
    u, v : ndarray of float64
        Lens-projected detector coordinates, counts (NaN where not defined).
    distance : ndarray of float64
        Optical path length in mm.
    cos_axis : ndarray of float64
        Cosine of the angle between the arriving ray and the optical axis.
    attenuation : ndarray of float64
        Fraction of the light that survives the path (1 direct, reflectance via a mirror).
    visible : ndarray of bool
        The spot falls on the detector and nothing blocks it.
    """

    u: F64
    v: F64
    distance: F64
    cos_axis: F64
    attenuation: F64
    visible: B

    def cameras(self, n: int) -> Spots:
        """The same spots for the first ``n`` cameras only (those a ``CAMS:`` setting uses)."""
        return Spots(
            self.u[:, :n],
            self.v[:, :n],
            self.distance[:, :n],
            self.cos_axis[:, :n],
            self.attenuation[:, :n],
            self.visible[:, :n],
        )


@dataclass
class Scene:
    """Motion, rig and optics of one simulated capture volume.

    Parameters
    ----------
    motion : Motion
        LED trajectories; LED id ``i`` is marker ``i`` of the motion.
    cameras : sequence of PsdCamera
        The rig.
    mirrors, occluders, intervals : sequences
        Reflecting planes, opaque spheres, scheduled occlusions.
    ambient : Ambient
        Ambient infrared light.
    """

    motion: Motion
    cameras: Sequence[PsdCamera]
    mirrors: Sequence[Mirror] = ()
    occluders: Sequence[SphereOccluder] = ()
    intervals: Sequence[OcclusionInterval] = ()
    ambient: Ambient = field(default_factory=Ambient)

    def __post_init__(self) -> None:
        if not self.cameras:
            raise ValueError("a scene needs at least one camera")
        self._R = np.stack([c.R for c in self.cameras])
        self._t = np.stack([c.t for c in self.cameras])
        self._centres = np.stack([c.center for c in self.cameras])
        self._f = np.array([c.focal for c in self.cameras])
        self._pp = np.array([c.principal for c in self.cameras])
        self._k = np.array([(c.k1, c.k2) for c in self.cameras])
        level = np.broadcast_to(np.asarray(self.ambient.level, np.float64), (self.n_cameras,))
        self._ambient_level = level.copy()

    @property
    def n_cameras(self) -> int:
        """Number of cameras in the rig."""
        return len(self.cameras)

    @property
    def n_leds(self) -> int:
        """Number of LEDs (markers) the motion carries."""
        return self.motion.n_markers

    def positions(self, times: F64, led_ids: I64) -> F64:
        """Positions of LEDs ``led_ids`` (N,) at scene times ``times`` (N,) s -> (N, 3) mm.

        LEDs the motion does not carry are NaN (not attached to anything).
        """
        ids = np.asarray(led_ids, dtype=np.int64)
        out = np.full((ids.size, 3), np.nan)
        known = ids < self.n_leds
        if known.any():
            out[known] = self.motion.sample(np.asarray(times, np.float64)[known], ids[known])
        return out

    def ambient_level(self, times: F64) -> F64:
        """Ambient power before differencing at scene times (N,) -> (N, C), intensity units."""
        a = self.ambient
        mod = 1.0 + a.flicker * np.sin(2.0 * np.pi * a.flicker_hz * np.asarray(times))
        return mod[:, None] * self._ambient_level[None, :]

    def _project(self, X: F64) -> tuple[F64, F64, F64, F64, B]:
        """World points (..., 3) -> u, v, distance, cos_axis, in_view, each (..., C)."""
        Xc = np.einsum("cij,...j->...ci", self._R, X) + self._t
        z = Xc[..., 2]
        dist = np.sqrt(np.einsum("...i,...i->...", Xc, Xc))
        with np.errstate(divide="ignore", invalid="ignore"):
            xn = Xc[..., 0] / z
            yn = Xc[..., 1] / z
            r2 = xn * xn + yn * yn
            d = 1.0 + self._k[:, 0] * r2 + self._k[:, 1] * r2 * r2
            u = self._f * xn * d + self._pp[:, 0]
            v = self._f * yn * d + self._pp[:, 1]
            cos_axis = z / dist
        in_view = (z > 1.0) & (u >= 0.0) & (u <= DETECTOR_MAX) & (v >= 0.0) & (v <= DETECTOR_MAX)
        return u, v, dist, cos_axis, in_view

    def _blocked(self, a: F64, b: F64) -> B:
        """Does any occluding sphere cut the segment a -> b? Broadcast shapes (..., 3) -> (...)."""
        ab = b - a
        shape = np.broadcast_shapes(a.shape, b.shape)[:-1]
        hit = np.zeros(shape, dtype=bool)
        len2 = np.maximum(np.einsum("...i,...i->...", ab, ab), 1e-12)
        for occ in self.occluders:
            s = np.asarray(occ.center, dtype=np.float64)
            lam = np.clip(np.einsum("...i,...i->...", s - a, ab) / len2, 0.0, 1.0)
            closest = a + lam[..., None] * ab
            dist2 = np.einsum("...i,...i->...", closest - s, closest - s)
            hit |= dist2 < occ.radius**2
        return hit

    def _hidden(self, times: F64, led_ids: I64) -> B:
        """Scheduled occlusions at scene times (N,) for LEDs (N,) -> (N, C)."""
        hidden = np.zeros((led_ids.size, self.n_cameras), dtype=bool)
        for iv in self.intervals:
            rows = (led_ids == iv.led) & (times >= iv.t0) & (times < iv.t1)
            if iv.camera is None:
                hidden[rows, :] = True
            else:
                hidden[rows, iv.camera] = True
        return hidden

    def spots(self, X: F64, times: F64, led_ids: I64) -> Spots:
        """Geometry of the light of LEDs at ``X`` (N, 3) mm at scene ``times`` (N,) s.

        Returns
        -------
        Spots
            Arrays of shape (N, C, 1 + number of mirrors).
        """
        n, c, s = X.shape[0], self.n_cameras, 1 + len(self.mirrors)
        u = np.full((n, c, s), np.nan)
        v = np.full((n, c, s), np.nan)
        dist = np.full((n, c, s), np.nan)
        cos_axis = np.zeros((n, c, s))
        att = np.zeros((n, c, s))
        vis = np.zeros((n, c, s), dtype=bool)
        hidden = self._hidden(np.asarray(times), np.asarray(led_ids))
        u[..., 0], v[..., 0], dist[..., 0], cos_axis[..., 0], vis[..., 0] = self._project(X)
        att[..., 0] = 1.0
        if self.occluders:
            vis[..., 0] &= ~self._blocked(X[:, None, :], self._centres[None, :, :])
        for j, m in enumerate(self.mirrors, start=1):
            p = np.asarray(m.point, dtype=np.float64)
            nrm = np.asarray(m.normal, dtype=np.float64)
            nrm = nrm / np.linalg.norm(nrm)
            sd = (X - p) @ nrm  # (N,) LED height above the plane
            sc = (self._centres - p) @ nrm  # (C,) camera height above the plane
            image = X - 2.0 * sd[:, None] * nrm
            uj, vj, dj, cj, inj = self._project(image)
            ok = inj & (sd[:, None] > 0.0) & (sc[None, :] > 0.0)
            if self.occluders and ok.any():
                lam = (sd[:, None] / (sd[:, None] + sc[None, :]))[..., None]
                hit = image[:, None, :] + lam * (self._centres[None, :, :] - image[:, None, :])
                ok &= ~self._blocked(X[:, None, :], hit)
                ok &= ~self._blocked(hit, self._centres[None, :, :])
            u[..., j], v[..., j], dist[..., j], cos_axis[..., j] = uj, vj, dj, cj
            att[..., j] = m.reflectance
            vis[..., j] = ok
        vis &= ~hidden[..., None]
        return Spots(u=u, v=v, distance=dist, cos_axis=cos_axis, attenuation=att, visible=vis)


def ring_rig(
    n_cameras: int,
    radius: float = 3500.0,
    height: float = 2200.0,
    target: tuple[float, float, float] = (0.0, 0.0, 900.0),
    focal: float = 3500.0,
    k1: float = -0.01,
    phase_deg: float = 0.0,
) -> list[PsdCamera]:
    """Cameras evenly spaced on a circle around the volume, all aimed at ``target``.

    Parameters
    ----------
    n_cameras : int
        1 to 4 (more work too).
    radius, height : float
        Circle radius and camera height, mm.
    target : tuple of float
        Point every optical axis passes through, mm.
    focal : float
        Focal length, detector counts.
    k1 : float
        Radial lens distortion.
    phase_deg : float
        Turns the whole ring about the vertical, degrees (camera ``i`` at azimuth
        ``45 + phase_deg + 360 i / n_cameras``): a second system of the same lab on
        other places.
    """
    cams = []
    for i in range(n_cameras):
        a = 2.0 * np.pi * i / n_cameras + np.pi / 4 + np.deg2rad(phase_deg)
        eye = (radius * np.cos(a), radius * np.sin(a), height)
        cams.append(PsdCamera.look_at(eye, target, focal=focal, name=f"cam{i}", k1=k1))
    return cams
