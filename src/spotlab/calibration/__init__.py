"""Calibration of cameras and rigs (DLT, SMAC, wand self-calibration); numpy and scipy only."""

from spotlab.calibration.dlt import (
    DISTORTION_TERMS,
    DltResult,
    dlt_calibrate,
    dlt_reconstruct_on_plane,
)

__all__ = ["DISTORTION_TERMS", "DltResult", "dlt_calibrate", "dlt_reconstruct_on_plane"]
