"""A flat cluster's identities tried with the references its links label (``TYPE-2.C3D``)."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from spotlab.reconstruction.identification import Link, MarkerModel
from spotlab.reconstruction.identification.handedness import Reference
from spotlab.reconstruction.identification.identity_trial import unrefused
from spotlab.reconstruction.identification.labelling import assign_labels
from spotlab.reconstruction.identification.model import Segment

#: A triangle A, B, C with AB = AC (B and C alike by their distances, as two hip markers
#: beside a sacrum), and markers D and E off it on no cluster (the right and left legs),
#: mirror images of each other across the triangle's plane of symmetry (y = 0).
LOCAL = np.array(
    [
        [0.0, 0.0, 0.0],
        [80.0, 40.0, 0.0],
        [80.0, -40.0, 0.0],
        [60.0, 50.0, 60.0],
        [60.0, -50.0, 60.0],
    ]
)
KW = {"tol_mm": 5.0, "rms_mm": 3.0, "margin_mm": 1.0}


def body_model(off_mm: float = 0.0) -> MarkerModel:
    """The triangle as a segment, D and E its references (side -1: the triangle's
    normal ``(B - A) x (C - A)`` points to -z), each linked to A, B, C within 3 mm of
    their distance plus ``off_mm``."""
    coords = LOCAL[:3] - LOCAL[:3].mean(axis=0)
    seg = Segment("pelvis", (0, 1, 2), coords)
    refs = []
    for m in (3, 4):
        v = LOCAL[m] - LOCAL[:3].mean(axis=0)
        refs.append(Reference(0, m, v / np.linalg.norm(v), 10.0, (0, 1, 2), -1))
    found = []
    for m in (3, 4):
        for n in range(3):
            d = float(np.linalg.norm(LOCAL[m] - LOCAL[n])) + off_mm
            found.append(Link(n, m, d - 3.0, d + 3.0))
    labels = ("A", "B", "C", "D", "E")
    return MarkerModel(labels, (seg,), tuple(found), 5.0, 6.0, references=tuple(refs))


def frame() -> tuple[np.ndarray, np.ndarray]:
    """The five markers turned and moved, shuffled: points (5, 3) mm and each one's marker."""
    R = Rotation.from_rotvec([0.3, -0.2, 0.9]).as_matrix()
    order = np.array([4, 2, 0, 3, 1])
    return LOCAL[order] @ R.T + np.array([1000.0, 500.0, 900.0]), order


def test_the_mirror_identity_is_refused_by_the_references_its_links_label() -> None:
    model = body_model()
    points, marker = frame()
    at = np.argsort(marker)  # point of each marker
    right, mirror = at[[0, 1, 2]], at[[0, 2, 1]]
    labels = np.full(5, -1)
    point_of = np.full(5, -1)

    def link_rounds(lab: np.ndarray, where: np.ndarray) -> None:
        # as the links label D and E: rightly after the right identity, each on the
        # other's point after the mirror one (their distances to A, B, C then fit)
        d, e = (at[3], at[4]) if where[1] == at[1] else (at[4], at[3])
        lab[d], lab[e], where[3], where[4] = 3, 4, d, e

    table = unrefused(model, 0, points, labels, point_of, np.array([right, mirror]), link_rounds)
    assert table.tolist() == [right.tolist()]


def test_a_cold_start_takes_the_identity_left_when_its_mirror_image_is_refused() -> None:
    points, marker = frame()
    # B and C alike: the two identities fit equally; before, the cluster waited
    assert assign_labels(body_model(), points, np.full(5, -1), **KW).tolist() == marker.tolist()


def test_with_no_reference_the_links_label_the_cluster_still_waits() -> None:
    points, _ = frame()
    got = assign_labels(body_model(off_mm=100.0), points, np.full(5, -1), **KW)
    assert (got == -1).all()
