"""``spotlab sim centroid --model-out``'s walk (simulators/centroid_truth_model.py): the
true markers of the hub the command serves, under the labels of its truth file."""

from __future__ import annotations

import numpy as np

from spotlab.simulators.centroid_service import CentroidSimOptions, build_centroid_device
from spotlab.simulators.centroid_truth_model import MODEL_SECONDS, model_walk


def test_the_model_walk_is_the_served_hubs_walk() -> None:
    labels, walk = model_walk(42, 3, rate_hz=20.0)
    served = build_centroid_device(CentroidSimOptions(markers=42, seed=3))
    assert labels == tuple(served.labels) and len(labels) == 42
    assert walk.shape == (round(MODEL_SECONDS * 20.0), 42, 3)
    t = np.arange(walk.shape[0]) / 20.0
    np.testing.assert_allclose(walk, served.positions(t), atol=1e-9)
    # the body walks (more than a metre in the 4 s), the two reference markers stay put
    assert np.ptp(walk[:, :40, :2], axis=0).max() > 1000.0
    assert np.ptp(walk[:, 40:], axis=0).max() < 1e-9
