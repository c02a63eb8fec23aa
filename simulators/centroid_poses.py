"""The simulated body standing still and moving every joint (``sim centroid --motion``).

A new subject's first labels come from a static trial and a range-of-motion (ROM) trial
(``spotlab model init`` / ``learn``). :class:`PosedBody` is the 40-marker body of
:class:`~spotlab.simulators.centroid_body.GaitBody` — the same subject for the same
seed: size, marker placement, soft tissue — in two motions besides the walk:

* ``static``: standing in a neutral pose (legs straight, arms hanging slightly away
  from the trunk) on a spot and with a heading drawn from the seed, swaying a few mm;
* ``rom``: on the same spot, first 1 s standing in the neutral pose (as a ROM trial
  starts; on a hub, time 0 is the capture's start, see
  :class:`~spotlab.simulators.centroid.CentroidDevice`), then, eased in over 1 s,
  stepping in place while turning slowly (0.08 turn a second): the walk's joints
  (:class:`~spotlab.simulators.motions.Gait`) through
  wider ranges (hip flexion +-0.55 rad, knee flexion to 0.8 rad, foot pitch following
  the shank +-0.15 rad, shoulder flexion +-0.5 rad; the walk's: +-0.4, 0.55, -, +-0.35)
  at 0.8 strides a second, and the joints the walk keeps still: elbow flexion 0.2 to
  0.7 rad (the walk's 0.3), shoulder abduction -0.05 to 0.25 rad and hip abduction
  -0.03 to 0.17 rad (the walk's 0), the pelvis 995-1075 mm high (the walk's 1005-1035;
  feet pressed into the floor stay on it, as in the walk).

A ROM trial's ranges have to hold the motion later labelled with the model learnt from
it: a marker whose distances leave the ranges learnt is not labelled.
"""

from __future__ import annotations

import numpy as np

from spotlab.simulators.centroid_body import F64, GaitBody
from spotlab.simulators.motions import body_pose

__all__ = ["BODY_MOTIONS", "STANDING_PELVIS_MM", "PosedBody", "body_for"]

#: Motions of the body: the walk of :class:`GaitBody`, then the two of :class:`PosedBody`.
BODY_MOTIONS = ("walk", "static", "rom")
#: Pelvis height standing with straight legs (mm): ankles 60 mm above the floor.
STANDING_PELVIS_MM = 1020.0
#: The ROM trial starts standing in the neutral pose for this long (s), then eases
#: into its motion over ROM_EASE_S.
ROM_NEUTRAL_S = 1.0
ROM_EASE_S = 1.0
#: Stride frequency of the ROM trial's stepping in place (Hz).
ROM_STRIDE_HZ = 0.8


class PosedBody(GaitBody):
    """Subject ``seed``'s body standing still (``static``) or in a ROM trial (``rom``).

    Parameters
    ----------
    motion : {"static", "rom"}
    seed : int
        The subject (as :meth:`GaitBody.for_seed`); its spot within 400 mm of the
        volume's centre and its heading come from the seed too.
    heading_rad, spot_mm : optional
        Override the seeded heading (rad, 0 = facing +x) and spot (x, y mm).
    """

    def __init__(
        self,
        motion: str,
        seed: int = 0,
        *,
        heading_rad: float | None = None,
        spot_mm: tuple[float, float] | None = None,
    ) -> None:
        if motion not in BODY_MOTIONS[1:]:
            raise ValueError(f"motion {motion!r}: expected one of {', '.join(BODY_MOTIONS[1:])}")
        walker = GaitBody.for_seed(seed)
        super().__init__(subject=walker.subject)
        self.motion = motion
        rng = np.random.default_rng(np.random.SeedSequence([seed, 0x5747]))
        heading, spot = float(rng.uniform(0, 2 * np.pi)), rng.uniform(-400, 400, 2)
        self.heading = heading if heading_rad is None else float(heading_rad)
        self.spot = np.asarray(spot if spot_mm is None else spot_mm, dtype=np.float64)

    def all_markers(self, t: F64) -> F64:
        """All 40 markers at times (K,) s -> (K, 40, 3) mm."""
        t = np.asarray(t, dtype=np.float64)
        side = np.array([0.0, np.pi])  # left, right out of phase
        ones = np.ones((t.size, 2))
        # neutral: legs straight, arms hanging slightly away from the trunk
        pose = {"hip": 0.02 * ones, "knee": 0.04 * ones, "foot": 0.0 * ones,
                "arm": 0.05 * ones, "elbow": 0.15 * ones, "hip_abd": 0.0 * ones,
                "arm_abd": 0.12 * ones}  # fmt: skip
        sway = np.stack([4 * np.sin(2 * np.pi * 0.23 * t + 0.3),
                         3 * np.sin(2 * np.pi * 0.17 * t + 1.1)], 1)  # fmt: skip
        heading = self.heading + 0.01 * np.sin(2 * np.pi * 0.11 * t)
        pel_z = STANDING_PELVIS_MM - 2 + 2 * np.cos(2 * np.pi * 0.3 * t)
        if self.motion == "rom":
            # ROM_NEUTRAL_S standing, then every joint eased into its range of motion
            e = np.clip((t - ROM_NEUTRAL_S) / ROM_EASE_S, 0.0, 1.0)
            e = e * e * (3 - 2 * e)
            p = 2 * np.pi * ROM_STRIDE_HZ * t[:, None] + side  # stride phase, (K, 2)
            q = 2 * np.pi * t[:, None]
            moving = {  # the walk's joints (simulators.motions.Gait), wider, and more
                "hip": 0.55 * np.sin(p),
                "knee": 0.4 * (1 - np.cos(p + 0.6)),
                "foot": 0.5 * (0.55 * np.sin(p) - 0.4 * (1 - np.cos(p + 0.6)))
                + 0.15 * np.sin(q * 0.7 + side),
                "arm": -0.5 * np.sin(p),
                "elbow": 0.45 - 0.25 * np.cos(q * 0.5 + side),
                "hip_abd": 0.1 * (1 - np.cos(q * 0.4 + 2.0)) - 0.03,
                "arm_abd": 0.15 * (1 - np.cos(q * 0.3 + 0.7)) - 0.05,
            }
            pose = {k: v + e[:, None] * (moving[k] - v) for k, v in pose.items()}
            heading = heading + 2 * np.pi * 0.08 * np.maximum(t - ROM_NEUTRAL_S, 0.0) * e
            ph = 2 * np.pi * ROM_STRIDE_HZ * t
            pel_z = pel_z + e * (1035.0 + 15.0 * np.cos(2 * ph) - 30 * np.cos(0.4 * ph) - pel_z)
            sway = sway * (1 - e[:, None])
        g = body_pose(
            self.spot + sway, _unit(heading), pel_z, pose["hip"], pose["knee"], pose["foot"],
            pose["arm"], elbow=pose["elbow"], hip_abd=pose["hip_abd"], arm_abd=pose["arm_abd"],
        )  # fmt: skip
        return self.dress(g, t)


def _unit(heading: F64) -> F64:
    """Headings (K,) rad -> unit vectors (K, 2) on the floor."""
    return np.stack([np.cos(heading), np.sin(heading)], 1)


def body_for(motion: str, seed: int) -> GaitBody:
    """The body of subject ``seed`` in ``motion`` (one of :data:`BODY_MOTIONS`)."""
    if motion == "walk":
        return GaitBody.for_seed(seed)
    return PosedBody(motion, seed)
