"""The rigs the frame-kernel tests compare kernel and numpy twin on."""

from __future__ import annotations

import numpy as np

from spotlab.geometry import Camera, Rig
from spotlab.simulators.rigs import ring_rig


def kernel_rigs() -> dict[str, Rig]:
    """Distorted 8-camera ring, the same without distortion, one with a skewed and a
    pinhole camera among distorted ones, and two cameras."""
    rig = ring_rig(8)
    cams = list(rig.cameras)
    K = cams[0].K.copy()
    K[0, 1] = 0.5
    mixed = list(cams)
    mixed[0] = Camera(K, cams[0].dist, cams[0].R, cams[0].t, cams[0].size, "skewed")
    mixed[1] = Camera(cams[1].K, np.zeros(5), cams[1].R, cams[1].t, cams[1].size, "pinhole")
    return {
        "distorted": rig,
        "pinhole": ring_rig(8, distortion=False),
        "skewed-and-pinhole": Rig(mixed),
        "two cameras": ring_rig(2, seed=3),
    }
