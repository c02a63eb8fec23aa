"""Reconstruction: triangulation, rigid bodies, other sensors; numpy and scipy only."""
