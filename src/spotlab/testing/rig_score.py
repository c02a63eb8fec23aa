"""The score of a calibrated rig on a synthetic wand dance's held-out data.

The final scoring step of the calibration benchmarks and tests: it reads the dance's
truth (held-out wand frames, body markers), which the simulators make and nothing but
scoring may read, and triangulates with the rig under test.
"""

from __future__ import annotations

import numpy as np

from spotlab.geometry import Rig
from spotlab.reconstruction import triangulate
from spotlab.simulators.wand_dance import WandDance

__all__ = ["score_rig"]


def score_rig(rig: Rig, dance: WandDance, *, aligned: bool = False) -> dict[str, float]:
    """Accuracy of a calibrated rig on the held-out data of a wand dance.

    Parameters
    ----------
    rig : Rig
        A calibration to score (the dance's own ``rig`` gives the noise floor).
    dance : WandDance
        The data set.
    aligned : bool
        Rigidly align the triangulated body markers to the truth before measuring
        their error, which removes any error of the world frame.

    Returns
    -------
    dict
        ``wand_length_rms_mm`` (held-out wand length error), ``body_rms_mm`` (3-D error
        of the body markers) and ``reprojection_rms_px`` (held-out frames, per
        coordinate); all from ODLE triangulation.
    """
    held = dance.held_out_wand
    C = len(rig)
    uv = held.transpose(1, 0, 2, 3).reshape(C, -1, 2)
    X = triangulate(rig, uv)
    ends = X.reshape(-1, 2, 3)
    lengths = np.linalg.norm(ends[:, 1] - ends[:, 0], axis=1)
    wand = float(np.sqrt(np.nanmean((lengths - dance.wand_length) ** 2)))
    reproj = float(np.sqrt(np.nanmean((rig.project(X) - uv) ** 2)))
    B = dance.body
    Xb = triangulate(rig, B.transpose(1, 0, 2, 3).reshape(C, -1, 2))
    truth = dance.body_true.reshape(-1, 3)
    ok = np.all(np.isfinite(Xb), axis=1)
    Xb, truth = Xb[ok], truth[ok]
    if aligned:
        u, _, vt = np.linalg.svd((truth - truth.mean(0)).T @ (Xb - Xb.mean(0)))
        R = u @ np.diag([1.0, 1.0, float(np.linalg.det(u @ vt))]) @ vt
        Xb = (Xb - Xb.mean(0)) @ R.T + truth.mean(0)
    body = float(np.sqrt(np.mean(np.sum((Xb - truth) ** 2, axis=1))))
    return {"wand_length_rms_mm": wand, "body_rms_mm": body, "reprojection_rms_px": reproj}
