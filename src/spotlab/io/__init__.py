"""Recording journals and exchange files (C3D, TRC, calibration files)."""
