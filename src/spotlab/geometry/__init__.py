"""Camera model and rigs: projection, distortion, DLT, calibration files are in spotlab.io."""
