"""Reconstruction: triangulation, rigid bodies, other sensors; numpy and scipy only."""

from spotlab.reconstruction.triangulation import (
    METHODS,
    TriangulationResult,
    triangulate,
    triangulate_points,
)

__all__ = ["METHODS", "TriangulationResult", "triangulate", "triangulate_points"]
