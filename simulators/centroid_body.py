"""A 40-marker walking body for the video-centroid simulator, with body segments that occlude.

:class:`GaitBody` places 40 Plug-in-Gait-like full-body markers on the walking
model of :class:`~spotlab.simulators.motions.Gait` (its 19 markers, plus 21
placed on the segments between them: thigh, tibia, upper arm, forearm, wrist
bar, finger, PSIS, head, back and chest markers, offset from the segment
axis the way wands and skin markers are). :meth:`GaitBody.segments` gives the
body's limbs and trunk as capsules (axis end points and radius, mm) at any
time: a camera does not see a marker when its line of sight passes through a
capsule the marker is not on.

Each seed of the simulator is another subject (:class:`Subject`): body size, walking
speed and stride, where each marker sits (about a centimetre off its nominal spot)
and how it moves on the skin; seed 0 is the nominal body.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from spotlab.simulators.motions import GAIT_LABELS, Gait, Motion

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]

EXTRA_LABELS = (
    "LTHI", "RTHI", "LTIB", "RTIB", "LUPA", "RUPA", "LFRM", "RFRM", "LWRB", "RWRB",
    "LFIN", "RFIN", "LPSI", "RPSI", "LFHD", "RFHD", "LBHD", "RBHD", "T10", "CLAV", "STRN",
)  # fmt: skip
BODY_LABELS = GAIT_LABELS + EXTRA_LABELS
_G = {name: i for i, name in enumerate(BODY_LABELS)}
#: Capsules: (end marker a, end marker b, radius mm); a marker on either end is on it.
SEGMENTS = (
    ("LASI", "LKNE", 70.0), ("RASI", "RKNE", 70.0), ("LKNE", "LANK", 50.0),
    ("RKNE", "RANK", 50.0), ("LSHO", "LELB", 45.0), ("RSHO", "RELB", 45.0),
    ("LELB", "LWRA", 35.0), ("RELB", "RWRA", 35.0), ("SACR", "C7", 130.0),
)  # fmt: skip
#: Markers on soft tissue (thigh and shank wands, upper arms): they move most on the skin.
SOFT_TISSUE = ("LTHI", "RTHI", "LTIB", "RTIB", "LUPA", "RUPA", "LKNE", "RKNE")
#: Markers carried by each capsule besides its ends (they sit on its surface).
SEGMENT_MARKERS = {
    0: ("LTHI",), 1: ("RTHI",), 2: ("LTIB",), 3: ("RTIB",), 4: ("LUPA",), 5: ("RUPA",),
    6: ("LFRM", "LWRB"), 7: ("RFRM", "RWRB"),
    8: ("LASI", "RASI", "LPSI", "RPSI", "T10", "CLAV", "STRN", "LSHO", "RSHO"),
}  # fmt: skip


#: Lowest height of a marker's centre (mm): a marker on a shoe pressed to the floor.
FLOOR_MARKER_MM = 5.0


def _on_the_floor(X: F64) -> F64:
    """Markers (..., 3) mm with none below ``FLOOR_MARKER_MM``: a toe marker placed
    low on a subject's shoe rests on the floor instead of passing through it."""
    out = np.array(X, dtype=np.float64)
    out[..., 2] = np.maximum(out[..., 2], FLOOR_MARKER_MM)
    return out


@dataclass(frozen=True)
class Subject:
    """What makes one simulated subject differ from the nominal body.

    Attributes
    ----------
    scale : float
        Body size relative to the nominal body (about 0.85-1.15).
    speed : float
        Walking speed (m/s).
    stride_hz : float
        Strides per second (the stride length follows the legs' length).
    offsets_mm : ndarray, shape (40, 3)
        Where each marker sits off its nominal spot, in the body's (forward, left,
        up) frame (mm; a lab's marker placement varies by about a centimetre).
    skin_amp_mm, skin_phase : ndarray, shape (40, 3)
        Soft-tissue motion: each coordinate swings at the stride frequency with this
        amplitude (mm; larger on thighs and shanks) and phase (rad).
    """

    scale: float
    speed: float
    stride_hz: float
    offsets_mm: F64
    skin_amp_mm: F64
    skin_phase: F64

    @classmethod
    def draw(cls, seed: int) -> Subject:
        """Subject ``seed``, drawn from its own random stream."""
        rng = np.random.default_rng(np.random.SeedSequence([seed, 0x5B7C]))
        scale = float(rng.uniform(0.85, 1.15))
        speed = float(rng.uniform(0.9, 1.5))
        stride_m = 1.35 * scale * float(rng.uniform(0.92, 1.08))
        amp = np.full(len(BODY_LABELS), 2.0)
        amp[[_G[n] for n in SOFT_TISSUE]] = 6.0
        return cls(
            scale=scale, speed=speed, stride_hz=speed / stride_m,
            offsets_mm=rng.normal(0.0, 8.0, (len(BODY_LABELS), 3)),
            skin_amp_mm=amp[:, None] * rng.uniform(0.5, 1.0, (len(BODY_LABELS), 3)),
            skin_phase=rng.uniform(0.0, 2 * np.pi, (len(BODY_LABELS), 3)),
        )  # fmt: skip

    def skin_mm(self, t: F64) -> F64:
        """Soft-tissue displacement at times (K,) s -> (K, 40, 3) mm, in the body frame."""
        w = 2 * np.pi * self.stride_hz
        return np.asarray(self.skin_amp_mm * np.sin(w * t[:, None, None] + self.skin_phase))


class GaitBody(Motion):
    """40 markers on a body walking on a circle (see the module docstring).

    Parameters
    ----------
    speed, radius, stride_hz : float
        As :class:`~spotlab.simulators.motions.Gait` (m/s, mm, Hz).
    subject : Subject, optional
        The subject's size, marker placement and soft tissue; None: the nominal body.
    """

    def __init__(
        self,
        speed: float = 1.2,
        radius: float = 1200.0,
        stride_hz: float = 0.9,
        *,
        subject: Subject | None = None,
    ) -> None:
        self._gait = Gait(speed, radius, stride_hz)
        self.n_markers = len(BODY_LABELS)
        self.labels = BODY_LABELS
        self.subject = subject

    @classmethod
    def for_seed(cls, seed: int, radius: float = 1200.0) -> GaitBody:
        """The walking body of subject ``seed``: seed 0 is the nominal body, every other
        seed another subject (size, walking speed, marker placement, soft tissue)."""
        if seed == 0:
            return cls(radius=radius)
        subject = Subject.draw(seed)
        return cls(subject.speed, radius, subject.stride_hz, subject=subject)

    def all_markers(self, t: F64) -> F64:
        """All 40 markers at times (K,) -> (K, 40, 3) mm."""
        t = np.asarray(t, dtype=np.float64)
        return self.dress(self._gait._all(t), t)

    def dress(self, g: F64, t: F64) -> F64:
        """The 40 markers from the 19 of :class:`Gait`'s body ``g`` (K, 19, 3) mm at times
        (K,) s: the 21 placed between them, then the subject (size, placement, skin)."""
        p = {name: g[:, i] for i, name in enumerate(GAIT_LABELS)}
        left = p["LASI"] - p["RASI"]
        left /= np.linalg.norm(left, axis=1, keepdims=True)
        up = np.zeros_like(left)
        up[:, 2] = 1.0
        fwd = np.cross(left, up)

        def mid(a: str, b: str, frac: float, lat: float, ahead: float = 0.0) -> F64:
            return p[a] + frac * (p[b] - p[a]) + lat * left + ahead * fwd

        extra = {}
        for s, lat in (("L", 1.0), ("R", -1.0)):
            extra[s + "THI"] = mid(s + "ASI", s + "KNE", 0.55, 40 * lat, 15)
            extra[s + "TIB"] = mid(s + "KNE", s + "ANK", 0.5, 35 * lat, 25)
            extra[s + "UPA"] = mid(s + "SHO", s + "ELB", 0.5, 40 * lat, -20)
            extra[s + "FRM"] = mid(s + "ELB", s + "WRA", 0.5, 30 * lat, 25)
            extra[s + "WRB"] = mid(s + "ELB", s + "WRA", 1.0, -35 * lat, -25)
            extra[s + "FIN"] = mid(s + "ELB", s + "WRA", 1.35, 0.0)
            extra[s + "PSI"] = p["SACR"] + 55 * lat * left - 20 * fwd
            extra[s + "FHD"] = p["HEAD"] + 60 * lat * left + 40 * fwd - 40 * up
            extra[s + "BHD"] = p["HEAD"] + 60 * lat * left - 90 * fwd - 40 * up
        extra["T10"] = mid("SACR", "C7", 0.5, 0.0, -40)
        extra["CLAV"] = 0.5 * (p["LSHO"] + p["RSHO"]) + 110 * fwd - 40 * up
        extra["STRN"] = extra["CLAV"] - 170 * up + 20 * fwd
        X = np.concatenate([g, np.stack([extra[k] for k in EXTRA_LABELS], 1)], axis=1)
        if self.subject is None:
            return _on_the_floor(X)
        # The subject: scaled about the point on the floor below the pelvis, markers
        # placed off their nominal spots and moving on the skin, in the body's frame.
        origin = 0.25 * (p["LASI"] + p["RASI"] + extra["LPSI"] + extra["RPSI"])
        origin[:, 2] = 0.0
        frame = np.stack([fwd, left, up], axis=1)  # (K, 3 axes, 3)
        local = self.subject.offsets_mm + self.subject.skin_mm(np.asarray(t, np.float64))
        return _on_the_floor(
            origin[:, None, :]
            + self.subject.scale * (X - origin[:, None, :])
            + np.einsum("kmi,kij->kmj", local, frame)
        )

    def sample(self, times: F64, markers: I64) -> F64:
        t = np.asarray(times, dtype=np.float64)
        return np.asarray(self.all_markers(t)[np.arange(t.size), np.asarray(markers, np.int64)])


def segment_capsules(markers: F64) -> tuple[F64, F64, F64]:
    """The body's capsules from one frame's 40 markers (40, 3) mm.

    Returns
    -------
    a, b : ndarray, shape (K, 3)
        Axis end points (mm).
    radius : ndarray, shape (K,)
        Radii (mm).
    """
    return markers[_SEG_A], markers[_SEG_B], _SEG_RADIUS


_SEG_A = np.array([_G[a] for a, _, _ in SEGMENTS])
_SEG_B = np.array([_G[b] for _, b, _ in SEGMENTS])
_SEG_RADIUS = np.array([r for _, _, r in SEGMENTS])
_SEG_RADIUS.flags.writeable = False


def carried_by(n_markers: int) -> npt.NDArray[np.bool_]:
    """(M, K): marker ``m`` is on capsule ``k`` (an end or a surface marker of it)."""
    on = np.zeros((n_markers, len(SEGMENTS)), dtype=bool)
    for k, (a, b, _) in enumerate(SEGMENTS):
        for name in (a, b, *SEGMENT_MARKERS.get(k, ())):
            if _G[name] < n_markers:
                on[_G[name], k] = True
    return on
