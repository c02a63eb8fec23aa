"""Reconstruction: triangulation, rigid bodies, other sensors; numpy and scipy only."""

from spotlab.reconstruction._rigid_identity import IdentityChoice, choose_identity
from spotlab.reconstruction._rigid_images import ImagePose, fit_body_to_images
from spotlab.reconstruction.planes import PlaneIntersection, intersect_planes, linear_sensor_plane
from spotlab.reconstruction.rigid import RigidPose, rigid_fit, rigid_pose
from spotlab.reconstruction.scanner import scanner_angles, scanner_position, scanner_precision
from spotlab.reconstruction.triangulation import (
    METHODS,
    TriangulationResult,
    triangulate,
    triangulate_points,
)

__all__ = [
    "METHODS",
    "IdentityChoice",
    "ImagePose",
    "PlaneIntersection",
    "RigidPose",
    "TriangulationResult",
    "choose_identity",
    "fit_body_to_images",
    "intersect_planes",
    "linear_sensor_plane",
    "rigid_fit",
    "rigid_pose",
    "scanner_angles",
    "scanner_position",
    "scanner_precision",
    "triangulate",
    "triangulate_points",
]
