"""Reconstruction: triangulation, rigid bodies, other sensors; numpy and scipy only."""

from spotlab.reconstruction._rigid_identity import IdentityChoice, choose_identity
from spotlab.reconstruction._rigid_images import ImagePose, fit_body_to_images
from spotlab.reconstruction.rigid import RigidPose, rigid_fit, rigid_pose

__all__ = [
    "IdentityChoice",
    "ImagePose",
    "RigidPose",
    "choose_identity",
    "fit_body_to_images",
    "rigid_fit",
    "rigid_pose",
]
