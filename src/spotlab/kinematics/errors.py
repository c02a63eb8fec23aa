"""Errors of the kinematics package."""

from __future__ import annotations

from spotlab.core.errors import SpotlabError


class KinematicsError(SpotlabError, ValueError):
    """Kinematic input is degenerate (too few samples, unordered times, bad values)."""
