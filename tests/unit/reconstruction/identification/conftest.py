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
    """Clusters and links of the same subject (seed 3), learnt from other frames of its walk
    (1.2-3 s; the scenes the tests label end at 1 s): each seed is another subject."""
    training = centroid_scene(3.0, 100.0, seed=3)
    return MarkerModel.infer(training.labels, training.markers_mm[120:])
