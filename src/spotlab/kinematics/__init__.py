"""Kinematics: orientation angles, smoothing splines, error estimates; numpy and scipy only."""

from spotlab.kinematics.errors import KinematicsError
from spotlab.kinematics.spline import SmoothingSpline

__all__ = ["KinematicsError", "SmoothingSpline"]
