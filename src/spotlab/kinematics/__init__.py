"""Kinematics: orientation angles, smoothing splines, error estimates (numpy; compiled kernels
for the smoothing spline, with numpy/SciPy twins)."""

from spotlab.kinematics.angles import (
    OrientationAngles,
    SegmentAngles,
    limb_axes,
    orientation_angles,
    orientation_matrix,
    segment_angles,
    segment_angles_from_joints,
    segment_matrix,
)
from spotlab.kinematics.continuous import align_angle, continuous_angle
from spotlab.kinematics.error_estimates import (
    equivalent_sd,
    four_combinations,
    repeated_measurement_sd,
    rounding_sd,
    sigma2_tau,
)
from spotlab.kinematics.errors import KinematicsError
from spotlab.kinematics.spline import SmoothingSpline
from spotlab.kinematics.trial_smoothing import smooth_trial

__all__ = [
    "KinematicsError",
    "OrientationAngles",
    "SegmentAngles",
    "SmoothingSpline",
    "align_angle",
    "continuous_angle",
    "equivalent_sd",
    "four_combinations",
    "limb_axes",
    "orientation_angles",
    "orientation_matrix",
    "repeated_measurement_sd",
    "rounding_sd",
    "segment_angles",
    "segment_angles_from_joints",
    "segment_matrix",
    "sigma2_tau",
    "smooth_trial",
]
