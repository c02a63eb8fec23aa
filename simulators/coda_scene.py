"""What a CSX scanner sees in one scan: moving markers, crossings, noise and faults.

Written from ``docs/protocols/coda.md`` §1, not from the driver. Scanner frame
(mm): x along the base (mirror A's axis at ``x = -b/2``, B's at ``+b/2``), y
forward (depth), z up. The markers move smoothly about a point 3 m in front of
the unit (:func:`marker_positions`). In a scan starting at world time ``t0``
each mirror sweeps -20° to +20° over ``0.8 T`` and crosses a marker when its
angle equals the marker's angle *at that instant* (:func:`crossings`, a
fixed-point solve), so the three angles of one marker belong to three
instants. Angles get Gaussian noise whose standard deviation grows with
distance (a fainter marker: ``SIGMA0_COUNTS * max(1, r / R0_MM)`` counts,
times ``1 + 4 ambient``) before they are quantised to counts.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from spotlab.simulators import coda_wire as cw

F64 = npt.NDArray[np.float64]

#: Part of the scan period the mirrors sweep.
SWEEP_FRACTION = 0.8
#: Angle noise at and below ``R0_MM`` (counts, 1 sigma).
SIGMA0_COUNTS = 0.3
R0_MM = 2000.0
#: The plane (y, mm) a ghost is reflected in: a glossy back wall.
GHOST_WALL_Y_MM = 4500.0
_HALF_FOV = math.radians(cw.FOV_DEG / 2)


#: A static rigid reference object (an L-frame on a stand) every unit can see, by
#: marker ID (codes WR, WO, WY, WG): world positions, mm.
REFERENCE = {
    50: (-400.0, 3400.0, -500.0),
    51: (400.0, 3400.0, -500.0),
    52: (-400.0, 3400.0, 300.0),
    53: (-400.0, 3000.0, -500.0),
}
_REF_TABLE = np.full((cw.MAX_MARKERS + 1, 3), np.nan)
for _id, _p in REFERENCE.items():
    _REF_TABLE[_id] = _p


def marker_positions(ids: npt.NDArray[np.int64], t_s: F64) -> F64:
    """World positions (mm) of markers ``ids`` at world times ``t_s`` (broadcast together).

    The world (lab) frame is the scanner frame of a unit at the origin looking along
    +y; ``t_s`` is world time (the machine's monotonic clock, s), so that simulated
    units in separate processes see one scene. Each moving marker sits on a ring of
    radius 250 mm about (0, 3000, 0) at an angle set by its ID, and the ring sways:
    x by 150 mm at 0.4 Hz, depth by 250 mm at 0.25 Hz, z by 150 mm at 0.6 Hz, each
    marker with its own phase. The markers of :data:`REFERENCE` stand still.
    """
    k = ids.astype(np.float64)
    phi = k * 2.399963  # the golden angle: IDs spread around the ring
    x = 250.0 * np.cos(phi) + 150.0 * np.sin(2 * np.pi * 0.4 * t_s + 0.3 * k)
    y = 3000.0 + 250.0 * np.sin(2 * np.pi * 0.25 * t_s + 0.2 * k)
    z = 250.0 * np.sin(phi) + 150.0 * np.sin(2 * np.pi * 0.6 * t_s + 0.5 * k)
    moving = np.stack(np.broadcast_arrays(x, y, z), axis=-1)
    fixed = np.broadcast_to(_REF_TABLE[np.clip(ids, 0, cw.MAX_MARKERS)], moving.shape)
    return np.where(np.isfinite(fixed), fixed, moving)


@dataclass(frozen=True)
class Pose:
    """Where a unit stands in the world: its origin at ``origin`` (mm), turned ``yaw_deg``
    about the vertical, counter-clockwise seen from above (its +y towards world -x)."""

    yaw_deg: float = 0.0
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @property
    def rotation(self) -> F64:
        """Columns: the unit's axes in the world frame."""
        c, s = math.cos(math.radians(self.yaw_deg)), math.sin(math.radians(self.yaw_deg))
        return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])

    def to_unit(self, p_world: F64) -> F64:
        """World points (..., 3) in the unit's scanner frame."""
        return (p_world - np.asarray(self.origin)) @ self.rotation


def mirror_angles(p: F64, base_mm: float) -> F64:
    """(alpha_A, alpha_B, beta) (rad) of points ``p`` (..., 3) (coda.md §1)."""
    x, y, z = p[..., 0], p[..., 1], p[..., 2]
    return np.stack(
        [np.arctan2(x + base_mm / 2, y), np.arctan2(x - base_mm / 2, y), np.arctan2(z, y)], -1
    )


@dataclass(frozen=True)
class Crossings:
    """Each mirror's crossing of each marker in one scan.

    Attributes
    ----------
    dt_s : ndarray, shape (N, 3)
        Crossing instants after the scan start (s); NaN outside the field.
    angles : ndarray, shape (N, 3)
        The marker's true angles (rad) at its crossings.
    positions : ndarray, shape (N, 3, 3)
        The marker's true position (mm) at each mirror's crossing.
    """

    dt_s: F64
    angles: F64
    positions: F64


def crossings(
    ids: npt.NDArray[np.int64],
    t0_s: float,
    sweep_s: float,
    base_mm: float,
    ghost: bool = False,
    pose: Pose | None = None,
) -> Crossings:
    """Solve, for every marker and mirror, the instant the sweep meets the marker.

    ``ghost``: the marker's reflection in the wall at :data:`GHOST_WALL_Y_MM` (of the
    unit's frame); ``pose``: where the unit stands (default: at the world origin).
    Positions are returned in the unit's frame.
    """
    n = ids.shape[0]
    dt = np.full((n, 3), sweep_s / 2)
    for _ in range(4):  # the marker moves < 1 mm in a scan: converges at once
        p = marker_positions(ids[:, None], t0_s + dt)
        if pose is not None:
            p = pose.to_unit(p)
        if ghost:
            p = p * np.array([1.0, -1.0, 1.0]) + np.array([0.0, 2 * GHOST_WALL_Y_MM, 0.0])
        a = mirror_angles(p, base_mm)
        ang = np.stack([a[:, j, j] for j in range(3)], -1)
        dt = sweep_s * (ang + _HALF_FOV) / (2 * _HALF_FOV)
    inside = (ang > -_HALF_FOV) & (ang < _HALF_FOV)
    return Crossings(np.where(inside, dt, np.nan), ang, p)


def angle_sigma_counts(range_mm: F64, ambient: float) -> F64:
    """Angle noise (counts, 1 sigma) of markers at ``range_mm``."""
    return SIGMA0_COUNTS * np.maximum(1.0, range_mm / R0_MM) * (1.0 + 4.0 * ambient)


def measure(
    angles: F64, range_mm: F64, ambient: float, rng: np.random.Generator
) -> npt.NDArray[np.int64]:
    """Noisy angles quantised to counts (N, 3); :data:`~coda_wire.NOT_SEEN` outside the field."""
    sigma = angle_sigma_counts(range_mm, ambient)[:, None]
    c = cw.CENTRE_COUNT + np.degrees(angles) * cw.COUNTS / cw.FOV_DEG
    c = np.rint(c + sigma * rng.standard_normal(angles.shape))
    c = np.where(np.isfinite(c) & (c >= 0) & (c < cw.COUNTS), c, cw.NOT_SEEN)
    return c.astype(np.int64)


def counts_to_rad(counts: npt.NDArray[np.int64]) -> F64:
    """Counts to radians (coda.md §1); NaN for not seen."""
    rad = np.radians((counts - cw.CENTRE_COUNT) * cw.FOV_DEG / cw.COUNTS)
    return np.where(counts == cw.NOT_SEEN, np.nan, rad)


def device_xyz(counts: npt.NDArray[np.int64], base_mm: float) -> tuple[F64, npt.NDArray[np.bool_]]:
    """The unit's own 3-D (mm) from measured counts (N, 3), and where it is valid."""
    a = counts_to_rad(counts)
    ta, tb, tc = np.tan(a[:, 0]), np.tan(a[:, 1]), np.tan(a[:, 2])
    valid = np.isfinite(a).all(axis=1) & (ta > tb)
    gap = np.where(valid, ta - tb, 1.0)
    y = base_mm / gap
    xyz = np.stack([-base_mm / 2 + y * ta, y, y * tc], -1)
    return np.where(valid[:, None], xyz, 0.0), valid
