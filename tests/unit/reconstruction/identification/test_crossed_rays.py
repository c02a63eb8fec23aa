"""Points of two rays, one of whose blobs another point explains, take no label by links."""

from __future__ import annotations

import numpy as np

from spotlab.geometry import Rig
from spotlab.reconstruction.identification import MarkerModel, RigGeometry
from spotlab.reconstruction.identification.crossed_rays import crossed_rays
from spotlab.reconstruction.identification.labelling import assign_labels
from spotlab.testing.centroid_scene import CentroidScene


def test_two_rays_of_two_markers_make_a_flagged_point(rig: Rig) -> None:
    geom = RigGeometry(rig)
    C = len(rig)
    markers = np.array([[0.0, 0.0, 500.0], [0.0, 120.0, 500.0], [600.0, 0.0, 900.0]])
    xy = geom.project(markers).reshape(-1, 2)  # blob of marker m in camera c: c * 3 + m
    index = np.full((C, 4), -1, dtype=np.intp)
    kept = np.zeros((C, 4), dtype=bool)
    for m, cams in enumerate([[0, 1, 2, 3], [0, 1, 2, 3], [4, 6]]):  # the third: 2 cameras
        index[cams, m] = np.array(cams) * 3 + m
        kept[cams, m] = True
    index[0, 3], index[2, 3] = 0 * 3 + 0, 2 * 3 + 1  # camera 0's blob of A, camera 2's of B
    kept[[0, 2], 3] = True
    rays = np.zeros((C, 4, 2))
    rays[kept] = xy[index[kept]]
    X, _, _ = geom.triangulate(rays, kept, max_ray_px=1e9)
    np.testing.assert_allclose(X[:3], markers, atol=1e-6)
    assert np.linalg.norm(X[3] - markers, axis=1).min() > 20  # where no marker is
    out = crossed_rays(geom, X, np.ones(4, dtype=bool), index, kept, xy, gate_px=3.0, apart_mm=5.0)
    # the two-camera marker far from the others keeps its chance of a label by links
    assert out.tolist() == [False, False, False, True]
    # points that are not current (missed, reflections) explain nothing
    out = crossed_rays(geom, X, np.array([False, False, True, True]), index, kept, xy, 3.0, 5.0)
    assert out.tolist() == [False, False, False, False]


def test_a_point_held_out_of_the_links_is_not_labelled_by_them(
    model: MarkerModel, scene: CentroidScene
) -> None:
    truth = scene.markers_mm[50]
    m = model.labels.index("LTHI")
    labels = np.arange(40, dtype=np.intp)
    labels[m] = -1  # LTHI lost, its point back as unlabelled
    kw = {"tol_mm": 5.0, "rms_mm": 3.0, "margin_mm": 1.0}
    assert assign_labels(model, truth, labels, **kw)[m] == m
    linkable = np.ones(40, dtype=bool)
    linkable[m] = False
    out = assign_labels(model, truth, labels, linkable=linkable, **kw)
    assert out[m] == -1 and (out[np.arange(40) != m] == labels[np.arange(40) != m]).all()
