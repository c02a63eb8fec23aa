"""The world a WSX hub sees: position sensors of three linear CCDs, moving markers.

Geometry (mm, the device frame: z up, the volume's centre at (0, 0, 1000)):
``S`` position sensors stand on a circle of radius 3 m at 1.6 m height, aimed at
the centre. Each is a bar with CCD 0 at x = -450 mm and CCD 2 at +450 mm, toed
in by 8.5 degrees and measuring along the bar, and CCD 1 in the middle measuring
up. Each CCD has its own principal distance and point (the factory calibration
holds them). ``M`` markers sit on a rigid body that drifts and turns through the
volume. A reading is ``r = f x[axis] / x[2] + r0`` in the CCD frame, plus the
sensor model of :meth:`WsxScene.readings` (docs/protocols/wsx.md §5).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from spotlab.simulators import wsx_wire as w

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

CENTRE = np.array([0.0, 0.0, 1000.0])
RADIUS_MM, HEIGHT_MM, HALF_BASE_MM, TOE_DEG = 3000.0, 1600.0, 450.0, 8.5


def _look_at(eye: F64, target: F64) -> F64:
    """World -> sensor rotation: z towards the target, y up-ish, x = y x z."""
    z = target - eye
    z /= np.linalg.norm(z)
    up = np.array([0.0, 0.0, 1.0])
    x = np.cross(up, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return np.stack([x, y, z])


def _rot_y(deg: float) -> F64:
    a = np.radians(deg)
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


@dataclass
class CcdGeometry:
    """True calibration of every CCD, flattened over sensors (C = 3 S).

    Attributes
    ----------
    R : ndarray, shape (C, 3, 3)
        World -> CCD rotations.
    t : ndarray, shape (C, 3)
        Translations (mm).
    focal, principal : ndarray, shape (C,)
        Principal distance and point (px).
    axis : ndarray of int, shape (C,)
        Measured axis (0 x, 1 y).
    sensor_R, sensor_eye : ndarray, shape (S, 3, 3) and (S, 3)
        Each position sensor's body frame: ``Y = sensor_R (X - sensor_eye)``.
    """

    R: F64
    t: F64
    focal: F64
    principal: F64
    axis: I64
    sensor_R: F64
    sensor_eye: F64


def sensor_geometry(n_sensors: int, seed: int) -> CcdGeometry:
    """The CCDs of ``n_sensors`` position sensors around the volume."""
    rng = np.random.default_rng(seed + 7919)
    Rs, ts, f, r0, ax, bodies, eyes = [], [], [], [], [], [], []
    for s in range(n_sensors):
        phi = 2 * np.pi * s / max(n_sensors, 1) + 0.3
        eye = np.array([RADIUS_MM * np.cos(phi), RADIUS_MM * np.sin(phi), HEIGHT_MM])
        R_s = _look_at(eye, CENTRE)
        bodies.append(R_s)
        eyes.append(eye)
        for c, (dx, toe, axis) in enumerate(
            ((-HALF_BASE_MM, -TOE_DEG, 0), (0.0, 0.0, 1), (HALF_BASE_MM, TOE_DEG, 0))
        ):
            centre = eye + R_s.T @ np.array([dx, 0.0, 0.0])
            R = _rot_y(toe) @ R_s
            Rs.append(R)
            ts.append(-R @ centre)
            f.append(1750.0 + rng.normal(0.0, 8.0))
            r0.append(1024.0 + rng.normal(0.0, 6.0))
            ax.append(axis)
            del c
    return CcdGeometry(
        np.array(Rs), np.array(ts), np.array(f), np.array(r0), np.array(ax, dtype=np.int64),
        np.array(bodies), np.array(eyes),
    )  # fmt: skip


def body_points(n_markers: int, seed: int) -> F64:
    """Marker positions on the rigid body (M, 3) mm, in its own frame."""
    rng = np.random.default_rng(seed + 104729)
    return rng.uniform(-220.0, 220.0, size=(n_markers, 3))


@dataclass
class SensorModel:
    """The CCD read-out's imperfections.

    Attributes
    ----------
    noise_px : float
        Centroid noise (px RMS) at a peak of 2000 counts; it grows as 1/sqrt(peak).
    ambient : float
        Ambient light, counts added under every peak (raises the noise).
    occlusion : float
        Probability that a marker is hidden from a whole position sensor in a frame.
    reflection : float
        Probability of a reflection's extra peak on one CCD reading.
    """

    noise_px: float = 0.02
    ambient: float = 40.0
    occlusion: float = 0.003
    reflection: float = 0.002


class WsxScene:
    """Markers on a moving rigid body seen by the CCDs of ``n_sensors`` sensors."""

    def __init__(
        self, n_sensors: int, n_markers: int, seed: int = 0, model: SensorModel | None = None
    ) -> None:
        self.n_sensors, self.n_markers, self.seed = n_sensors, n_markers, seed
        self.geometry = sensor_geometry(n_sensors, seed)
        self.body = body_points(n_markers, seed)
        self.model = model if model is not None else SensorModel()
        self.rng = np.random.default_rng(seed)

    def positions(self, t_s: F64) -> F64:
        """Marker positions (..., M, 3) mm at times ``t_s`` (...) s."""
        t = np.asarray(t_s, dtype=np.float64)[..., None]
        centre = CENTRE + np.concatenate(
            [
                250.0 * np.sin(2 * np.pi * 0.21 * t),
                200.0 * np.sin(2 * np.pi * 0.13 * t + 1.0),
                120.0 * np.sin(2 * np.pi * 0.17 * t + 2.0),
            ],
            axis=-1,
        )
        yaw = 0.6 * np.sin(2 * np.pi * 0.11 * t)[..., 0]
        c, s = np.cos(yaw), np.sin(yaw)
        p = self.body
        x = c[..., None] * p[:, 0] - s[..., None] * p[:, 1]
        y = s[..., None] * p[:, 0] + c[..., None] * p[:, 1]
        z = np.broadcast_to(p[:, 2], x.shape)
        return np.stack([x, y, z], axis=-1) + centre[..., None, :]

    def ideal(self, points: F64) -> tuple[F64, F64]:
        """Noise-free readings (..., C) px and distances (..., C) mm of ``points`` (..., 3)."""
        g = self.geometry
        xs = np.einsum("cij,...j->...ci", g.R, points) + g.t
        num = np.where(g.axis == 0, xs[..., 0], xs[..., 1])
        depth = xs[..., 2]
        return g.focal * num / depth + g.principal, np.linalg.norm(xs, axis=-1)

    def readings(self, points: F64, setup: w.Setup) -> tuple[F64, I64, I64]:
        """What the CCDs report for markers at ``points`` (F, M, 3).

        Returns
        -------
        centroid : ndarray, shape (F, M, S, 3)
            px; NaN where there is no reading.
        peak, code : ndarray of int, shape (F, M, S, 3)
            Peak counts (0-4095) and quality code (wsx.md §5).
        """
        mdl, rng = self.model, self.rng
        r, dist = self.ideal(points)
        shape = r.shape
        duty = setup.duty_permille / 350.0
        volt = (setup.voltage_dv / 80.0) ** 2
        raw_peak = 2000.0 * (3000.0 / dist) ** 2 * setup.gain / 160.0 * duty * volt
        raw_peak *= rng.uniform(0.9, 1.1, size=shape)
        sigma = mdl.noise_px * np.sqrt((2000.0 + mdl.ambient) / np.maximum(raw_peak, 50.0))
        code = np.zeros(shape, dtype=np.int64)
        saturated = raw_peak > 4095.0
        sigma = np.where(saturated, 4.0 * sigma, sigma)
        centroid = r + rng.normal(size=shape) * sigma
        code[saturated] = w.TOO_LARGE
        peak = np.minimum(raw_peak + mdl.ambient, 4095.0).astype(np.int64)
        # reflections: an extra peak; the larger one's centroid is reported
        refl = rng.random(shape) < mdl.reflection
        strength = rng.uniform(0.3, 1.3, size=shape)
        flagged = refl & (strength >= 0.5)
        wrong = flagged & (strength > 1.0)
        centroid = np.where(wrong, centroid + rng.uniform(20.0, 200.0, size=shape), centroid)
        code[flagged] = w.EXTRA_PEAK
        small = raw_peak < setup.threshold * 16.0
        off = (centroid < 0.0) | (centroid > w.PIXELS - 1)
        F, M = shape[:2]
        S = self.n_sensors
        hidden = rng.random((F, M, S)) < mdl.occlusion
        hidden = np.repeat(hidden, w.CCDS, axis=-1)
        code[off] = w.OFF_DEVICE
        code[small | hidden] = w.TOO_SMALL
        missing = off | small | hidden
        centroid = np.where(missing, np.nan, centroid)
        peak = np.where(missing, 0, peak)
        if not setup.flags & w.FLAG_FULL_RAW:
            peak = np.zeros_like(peak)
            code = np.where(missing, w.TOO_SMALL, 0)
        return (
            centroid.reshape(F, M, S, w.CCDS),
            peak.reshape(F, M, S, w.CCDS),
            code.reshape(F, M, S, w.CCDS),
        )

    def calibration_record(self, sensor: int, registered: bool = True) -> bytes:
        """The factory calibration of one position sensor (wsx.md §4.4): its CCDs in the
        device frame, or (``registered`` false) in the sensor's own body frame."""
        g = self.geometry
        sl = slice(3 * sensor, 3 * sensor + 3)
        R, t = g.R[sl], g.t[sl]
        if not registered:  # X = B' Y + eye: x = R B' Y + (R eye + t)
            B, eye = g.sensor_R[sensor], g.sensor_eye[sensor]
            R, t = R @ B.T, np.einsum("cij,j->ci", R, eye) + t
        return w.encode_calibration(
            sensor, g.axis[sl], g.focal[sl], g.principal[sl], R, t, frame=0 if registered else 1
        )
