"""Calibration of cameras and rigs (DLT, SMAC, wand self-calibration); numpy and scipy only."""
