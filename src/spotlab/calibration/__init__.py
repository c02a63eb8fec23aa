"""Calibration of cameras and rigs (DLT, SMAC, wand self-calibration); numpy and scipy only."""

from spotlab.calibration.dlt import (
    DISTORTION_TERMS,
    DltResult,
    dlt_calibrate,
    dlt_reconstruct_on_plane,
)
from spotlab.calibration.iac import IacResult, intrinsics_from_orthogonal_vanishing_points
from spotlab.calibration.vanishing import vanishing_point

__all__ = [
    "DISTORTION_TERMS",
    "DltResult",
    "IacResult",
    "dlt_calibrate",
    "dlt_reconstruct_on_plane",
    "intrinsics_from_orthogonal_vanishing_points",
    "vanishing_point",
]
