"""A labelled track whose point two crossed rays make loses its label."""

from __future__ import annotations

import numpy as np

from spotlab.geometry import Rig
from spotlab.reconstruction.identification import BlobFrame, Identifier, MarkerModel, Segment
from spotlab.reconstruction.identification.model import Link


def _frame(rig: Rig, points: np.ndarray, cameras: list[list[int]]) -> BlobFrame:
    """Blobs of each point (rows) in its cameras, at the point's projection."""
    uv = rig.project(points)  # (C, K, 2)
    pairs = [(c, k) for k, cams in enumerate(cameras) for c in cams]
    return BlobFrame(np.array([uv[c, k] for c, k in pairs]), np.array([c for c, _ in pairs]))


def test_a_carried_label_does_not_stay_on_a_point_of_crossed_rays(rig: Rig) -> None:
    tri = np.array([[0.0, 0.0, 1000.0], [130.0, 0.0, 1000.0], [20.0, 90.0, 1000.0]])
    # the fourth marker, on no segment, behind A on camera 4's line of sight
    ray = tri[0] - rig[4].center
    e = tri[0] + ray / np.linalg.norm(ray) * 115.0
    reach = np.linalg.norm(tri - e, axis=1)
    model = MarkerModel(
        labels=("A", "B", "C", "E"),
        segments=(Segment("tri", (0, 1, 2), tri - tri.mean(axis=0)),),
        links=tuple(Link(m, 3, float(reach[m]) - 40, float(reach[m]) + 40) for m in range(3)),
    )
    identify = Identifier(rig, model, floor_mm=None, check_frames=0)
    points = np.vstack([tri, e])
    every = list(range(len(rig)))
    assert np.isfinite(identify(_frame(rig, points, [every] * 4)).points).all()
    # Next frame E is seen by cameras 4 and 1 only: its blob in camera 4 lies on A's
    # projection, so its point is one that two rays make, of which A explains one.
    second = identify(_frame(rig, points, [every] * 3 + [[4, 1]]))
    assert np.isfinite(second.points[:3]).all()
    assert np.isnan(second.points[3]).all()  # no label carried onto it
