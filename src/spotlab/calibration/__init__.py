"""Calibration of cameras and rigs (DLT, SMAC, wand self-calibration); numpy and scipy only."""

from spotlab.calibration.cage import CageCalibration, RotationCheck, cage_calibrate, rotation_check
from spotlab.calibration.dlt import (
    DISTORTION_TERMS,
    DltResult,
    dlt_calibrate,
    dlt_reconstruct_on_plane,
)
from spotlab.calibration.iac import IacResult, intrinsics_from_orthogonal_vanishing_points
from spotlab.calibration.linearisation import DetectorLinearisation, fit_linearisation
from spotlab.calibration.planar import PlanarCalibration, calibrate_intrinsics, fit_homography
from spotlab.calibration.report import quality_report
from spotlab.calibration.report_figure import write_report_figure
from spotlab.calibration.smac import SmacCalibration, smac_calibrate
from spotlab.calibration.vanishing import vanishing_point
from spotlab.calibration.wand import WandCalibration, wand_calibrate

__all__ = [
    "DISTORTION_TERMS",
    "CageCalibration",
    "DetectorLinearisation",
    "DltResult",
    "IacResult",
    "PlanarCalibration",
    "RotationCheck",
    "SmacCalibration",
    "WandCalibration",
    "cage_calibrate",
    "calibrate_intrinsics",
    "dlt_calibrate",
    "dlt_reconstruct_on_plane",
    "fit_homography",
    "fit_linearisation",
    "intrinsics_from_orthogonal_vanishing_points",
    "quality_report",
    "rotation_check",
    "smac_calibrate",
    "vanishing_point",
    "wand_calibrate",
    "write_report_figure",
]
