"""A short scene shared by the identification tests (built once per session)."""

from __future__ import annotations

import pytest

from spotlab.geometry import Rig
from spotlab.reconstruction.identification import MarkerModel
from spotlab.simulators.rigs import ring_rig
from spotlab.testing.synthetic_blobs import SyntheticBlobs, synthetic_blobs


@pytest.fixture(scope="session")
def rig() -> Rig:
    return ring_rig(8)


@pytest.fixture(scope="session")
def scene(rig: Rig) -> SyntheticBlobs:
    return synthetic_blobs(rig, 1.0, 300.0, seed=3, full_occlusion_per_s=0.5)


@pytest.fixture(scope="session")
def model(scene: SyntheticBlobs) -> MarkerModel:
    return MarkerModel.from_trajectories(scene.labels, scene.markers_mm[:10], scene.segments)
