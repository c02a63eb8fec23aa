"""Short scenes of the simulated CEN hub shared by the identification tests (built once)."""

from __future__ import annotations

import pytest

from spotlab.geometry import Rig
from spotlab.reconstruction.identification import MarkerModel
from spotlab.simulators.rigs import ring_rig
from spotlab.testing.centroid_scene import CentroidScene, centroid_scene


@pytest.fixture(scope="session")
def rig() -> Rig:
    return ring_rig(8)


@pytest.fixture(scope="session")
def scene() -> CentroidScene:
    """1 s of the walking body, with many reflections (ghost points below the floor)."""
    return centroid_scene(1.0, 300.0, seed=3, ghost_rate=0.3, noise_blobs=0.5)


@pytest.fixture(scope="session")
def model() -> MarkerModel:
    """Clusters and links learnt from another run's truth (a range-of-motion trial)."""
    training = centroid_scene(1.5, 100.0, seed=4)
    return MarkerModel.infer(training.labels, training.markers_mm, link_spread_mm=50.0)
