"""Kinematics: orientation angles, smoothing splines, error estimates; numpy and scipy only."""
