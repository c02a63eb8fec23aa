"""Dual-axis lateral-effect photodiode (PSD): light on the detector -> one SPX record.

A PSD has no pixels. Each axis has two electrodes; a light spot at normalised
position ``p`` in [-1, 1] splits its photocurrent ``P`` into ``P (1 + p) / 2``
and ``P (1 - p) / 2``. The electronics report ``(I+ - I-) / (I+ + I-)``, which
for several spots at once is the **power-weighted centroid of all light on
the detector** — direct spot, mirror images and un-differenced ambient light.
A reflection therefore biases the coordinate instead of appearing as a second
spot.

Model, vectorised over LEDs (N), cameras (C) and spots (S = 1 + mirrors):

* power per spot ``P = gain * I_led * attenuation * cos(theta)^n / d^2``
  (``I_led`` mA, ``d`` m, ``theta`` the angle to the optical axis);
* the detector's own non-linearity, a smooth radial pincushion per spot:
  ``p' = p (1 + k (p^2 + q^2))``;
* electrodes summed over spots plus ambient light at its centroid, each
  clipped at ``full_scale / 2`` (ADC saturation, which pulls the reading
  towards the centre); background differencing subtracts the dark sample's
  electrode currents;
* Gaussian noise of fixed SD on each electrode, so the coordinate noise
  ``~ noise / intensity`` grows as the intensity falls;
* 12-bit quantisation to 0-4094, ``0xFFF`` when not seen, SPX flags.

Lens distortion and detector pincushion together are a radial distortion of the
normalised image coordinates, so :meth:`PsdModel.rig` writes the simulated cameras
as a spotlab :class:`~spotlab.geometry.Rig` in detector counts: the truth a
calibration from the detector readings should find.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from spotlab.geometry import Camera, Rig
from spotlab.simulators import wire
from spotlab.simulators.scene import DETECTOR_CENTRE, DETECTOR_MAX, PsdCamera, Spots

F64 = npt.NDArray[np.float64]
U8 = npt.NDArray[np.uint8]
U16 = npt.NDArray[np.uint16]

HALF_RANGE = 2047.0


@dataclass
class PsdReading:
    """What the cameras report for one frame, arrays of shape (N, C).

    Attributes
    ----------
    x, y : ndarray of uint16
        Detector counts 0-4094, ``0xFFF`` when not valid.
    intensity : ndarray of uint8
        LED-on minus dark sample, 0-255.
    flags : ndarray of uint8
        SPX record flags (valid, saturated, low signal, ambient high, near edge).
    power : ndarray of float64
        Noise-free LED power on the detector (direct + reflections), intensity units.
    """

    x: U16
    y: U16
    intensity: U8
    flags: U8
    power: F64


@dataclass(frozen=True)
class PsdModel:
    """Parameters of the PSD cameras (the same for every camera of a rig).

    Parameters
    ----------
    gain : float
        Intensity units per mA of LED drive current at 1 m on the optical axis.
    vignetting_exponent : float
        ``n`` in the ``cos(theta)^n`` fall-off towards the edge of the field.
    pincushion : float
        Radial non-linearity of the detector, ``k`` above (0: linear).
    full_scale : float
        Light on the detector (both electrodes of an axis) at which the ADC
        saturates for a centred spot, intensity units.
    electrode_noise : float
        SD of the noise on each electrode, intensity units.
    low_signal : float
        Below this intensity a record is not valid (flag low signal).
    ambient_high : float
        Ambient power above which a record gets the ambient-high flag.
    edge_fraction : float
        Fraction of the half-range beyond which a record is flagged near the edge.
    """

    gain: float = 42.0
    vignetting_exponent: float = 4.0
    pincushion: float = 0.02
    full_scale: float = 300.0
    electrode_noise: float = 0.05
    low_signal: float = 8.0
    ambient_high: float = 60.0
    edge_fraction: float = 0.9

    def rig(self, cameras: Sequence[PsdCamera]) -> Rig:
        """The cameras as read through this detector: a spotlab rig in detector counts.

        Parameters
        ----------
        cameras : sequence of PsdCamera
            The simulated cameras (a scene's ``cameras``).

        Returns
        -------
        Rig
            Image size 4096 x 4096 counts, principal point and focal length of each
            camera, OpenCV distortion ``(k1 + c, k2 + 3 c k1, 0, 0, 3 c (k2 + k1^2))``
            with ``c = pincushion (focal / 2047)^2``.

        Notes
        -----
        The lens gives ``x_d = x_n (1 + a)``, ``a = k1 r^2 + k2 r^4``; the pincushion
        multiplies the detector offset by ``1 + c r_d^2`` with ``r_d = r (1 + a)``, so
        ``x = x_n (1 + a + c r^2 (1 + a)^3)``. The rig keeps its terms to ``r^6``; the
        rest, ``c r^8 (k1^3 + 6 k1 k2) + ...``, stays below 1e-4 count over the whole
        detector for the default rig (``k1 = -0.01``, focal 3500). The centre of the
        detector is exactly 2048 counts (the simulator uses 2048 and a half-range of
        2047): the pincushion is centred on the principal point only when it lies there.
        Readings clipped at the detector's edge (0 or 4094) or pulled towards the centre
        by saturation do not follow the rig.

        Raises
        ------
        ValueError
            If a camera's principal point is off the detector centre while the detector
            has a pincushion: the two then make no radial distortion.
        """
        out = []
        for i, cam in enumerate(cameras):
            if self.pincushion and tuple(cam.principal) != (DETECTOR_CENTRE, DETECTOR_CENTRE):
                raise ValueError(
                    f"camera {cam.name or i + 1}: principal point {cam.principal} is off the "
                    "detector centre, where the pincushion is centred"
                )
            c = self.pincushion * (cam.focal / HALF_RANGE) ** 2
            dist = (cam.k1 + c, cam.k2 + 3 * c * cam.k1, 0.0, 0.0, 3 * c * (cam.k2 + cam.k1**2))
            K = [[cam.focal, 0.0, cam.principal[0]], [0.0, cam.focal, cam.principal[1]], [0, 0, 1]]
            out.append(Camera(K, dist, cam.R, cam.t, (4096, 4096), name=cam.name or f"cam{i + 1}"))
        return Rig(out)

    def spot_power(self, spots: Spots, current_ma: F64) -> F64:
        """Power of every spot, shape (N, C, S), intensity units; 0 where not visible."""
        d_m = np.where(spots.visible, spots.distance, 1.0) * 1e-3
        cos = np.where(spots.visible, spots.cos_axis, 0.0)
        p = self.gain * np.asarray(current_ma)[:, None, None] * spots.attenuation
        return np.where(spots.visible, p * cos**self.vignetting_exponent / d_m**2, 0.0)

    def measure(
        self,
        spots: Spots,
        current_ma: F64,
        ambient_on: F64,
        ambient_dark: F64 | None,
        rng: np.random.Generator,
        ambient_centroid: tuple[float, float] = (DETECTOR_CENTRE, DETECTOR_CENTRE),
    ) -> PsdReading:
        """Read every camera during every LED's slot.

        Parameters
        ----------
        spots : Spots
            Geometry from :meth:`Scene.spots`, arrays (N, C, S).
        current_ma : ndarray, shape (N,)
            LED drive currents in mA.
        ambient_on : ndarray, shape (N, C)
            Ambient power during the LED-on sample.
        ambient_dark : ndarray, shape (N, C), or None
            Ambient power during the dark sample; ``None`` without background differencing.
        rng : numpy.random.Generator
            Noise source (the caller seeds it).
        ambient_centroid : tuple of float
            Where ambient light centres on the detectors, counts.

        Returns
        -------
        PsdReading
        """
        power = self.spot_power(spots, current_ma)  # (N, C, S)
        p = np.where(spots.visible, (spots.u - DETECTOR_CENTRE) / HALF_RANGE, 0.0)
        q = np.where(spots.visible, (spots.v - DETECTOR_CENTRE) / HALF_RANGE, 0.0)
        bend = 1.0 + self.pincushion * (p * p + q * q)
        p, q = p * bend, q * bend
        pa = (ambient_centroid[0] - DETECTOR_CENTRE) / HALF_RANGE
        qa = (ambient_centroid[1] - DETECTOR_CENTRE) / HALF_RANGE
        half = np.array([1.0, -1.0])  # electrode + and -
        # Electrode currents (N, C, 4): x+, x-, y+, y-; sum_s P_s (1 +- p_s) / 2 per electrode.
        total = power.sum(axis=-1)
        moments = np.stack([total, (power * p).sum(axis=-1), (power * q).sum(axis=-1)], axis=-1)
        mix = 0.5 * np.array([[1.0, 1.0, 1.0, 1.0], [1.0, -1.0, 0.0, 0.0], [0.0, 0.0, 1.0, -1.0]])
        amb = np.concatenate([0.5 * (1.0 + pa * half), 0.5 * (1.0 + qa * half)])  # (4,)
        i_max = self.full_scale / 2.0
        raw_on = moments @ mix + ambient_on[..., None] * amb
        on = np.minimum(raw_on, i_max)
        saturated = np.any(raw_on > i_max, axis=-1)
        if ambient_dark is not None:
            on = on - np.minimum(ambient_dark[..., None] * amb, i_max)
        d = on + rng.normal(0.0, self.electrode_noise, size=on.shape)
        sum_x, sum_y = d[..., 0] + d[..., 1], d[..., 2] + d[..., 3]
        level = 0.5 * (sum_x + sum_y)
        seen = spots.visible.any(axis=-1)
        valid = seen & (level >= self.low_signal) & (sum_x > 0) & (sum_y > 0)
        with np.errstate(divide="ignore", invalid="ignore"):
            xf = DETECTOR_CENTRE + HALF_RANGE * (d[..., 0] - d[..., 1]) / sum_x
            yf = DETECTOR_CENTRE + HALF_RANGE * (d[..., 2] - d[..., 3]) / sum_y
        xf = np.clip(np.where(valid, xf, 0.0), 0.0, DETECTOR_MAX)
        yf = np.clip(np.where(valid, yf, 0.0), 0.0, DETECTOR_MAX)
        x = np.where(valid, np.rint(xf), wire.INVALID).astype(np.uint16)
        y = np.where(valid, np.rint(yf), wire.INVALID).astype(np.uint16)
        edge = self.edge_fraction * HALF_RANGE
        near = valid & (
            (np.abs(xf - DETECTOR_CENTRE) > edge) | (np.abs(yf - DETECTOR_CENTRE) > edge)
        )
        flags = (
            np.where(valid, wire.FLAG_VALID, 0)
            | np.where(saturated | (level > 255.0), wire.FLAG_SATURATED, 0)
            | np.where(level < self.low_signal, wire.FLAG_LOW_SIGNAL, 0)
            | np.where(ambient_on > self.ambient_high, wire.FLAG_AMBIENT_HIGH, 0)
            | np.where(near, wire.FLAG_NEAR_EDGE, 0)
        ).astype(np.uint8)
        intensity = np.clip(np.rint(level), 0, 255).astype(np.uint8)
        return PsdReading(x=x, y=y, intensity=intensity, flags=flags, power=total)
