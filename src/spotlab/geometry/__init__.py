"""Camera model and rigs: projection, distortion, DLT parameters, rig calibration files."""
