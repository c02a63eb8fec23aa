"""Camera model and rigs: projection, distortion, DLT parameters, rig calibration files."""

from spotlab.geometry.camera import Camera, flip_dlt_v
from spotlab.geometry.distortion import distort_normalized, undistort_normalized
from spotlab.geometry.rig import Rig

__all__ = ["Camera", "Rig", "distort_normalized", "flip_dlt_v", "undistort_normalized"]
