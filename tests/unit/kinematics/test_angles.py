"""Yeadon's orientation and segment angles: definitions, round trips, singularities, errors."""

from __future__ import annotations

import doctest

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.spatial.transform import Rotation

from spotlab.kinematics import KinematicsError, angles
from spotlab.kinematics.angles import (
    limb_axes,
    orientation_angles,
    orientation_matrix,
    segment_angles,
    segment_angles_from_joints,
    segment_matrix,
)


def _rot(axis: int, angle: float) -> np.ndarray:
    """Right-hand rotation matrix about a coordinate axis (Yeadon's R_k(-angle))."""
    v = np.zeros(3)
    v[axis] = angle
    return Rotation.from_rotvec(v).as_matrix()


def _v(x: float, y: float, z: float) -> np.ndarray:
    return np.array([x, y, z])


def test_matrix_is_the_papers_product_of_rotations() -> None:
    # S_fi = R1(-phi) R2(-theta) R3(-psi), Yeadon's matrices written out
    phi, theta, psi = 0.4, -0.3, 2.0
    c, s = np.cos, np.sin
    R1 = np.array([[1, 0, 0], [0, c(phi), -s(phi)], [0, s(phi), c(phi)]])
    R2 = np.array([[c(theta), 0, s(theta)], [0, 1, 0], [-s(theta), 0, c(theta)]])
    R3 = np.array([[c(psi), -s(psi), 0], [s(psi), c(psi), 0], [0, 0, 1]])
    assert_allclose(orientation_matrix(phi, theta, psi), R1 @ R2 @ R3, atol=1e-15)
    # and Yeadon's element formulas: sin(theta) = F3(1), ...
    S = orientation_matrix(phi, theta, psi)
    assert_allclose(S[0, 2], s(theta))
    assert_allclose(S[2, 2], c(phi) * c(theta))
    assert_allclose(S[0, 0], c(theta) * c(psi))


def test_pure_somersault_tilt_twist_known_answers() -> None:
    # a pure rotation about one body axis is that angle alone
    for axis, name in enumerate(["somersault", "tilt", "twist"]):
        a = orientation_angles(_rot(axis, 0.7))
        got = {"somersault": a.somersault, "tilt": a.tilt, "twist": a.twist}
        for key, value in got.items():
            assert_allclose(value, 0.7 if key == name else 0.0, atol=1e-15)
    # a half somersault turns the body's long axis f3 upside down
    a = orientation_angles(orientation_matrix(np.pi, 0.0, 0.0))
    assert_allclose(abs(a.somersault), np.pi)
    assert_allclose(orientation_matrix(np.pi, 0.0, 0.0)[:, 2], [0.0, 0.0, -1.0], atol=1e-15)


def test_round_trip_over_the_whole_range() -> None:
    rng = np.random.default_rng(1)
    phi = rng.uniform(-np.pi, np.pi, 1000)
    theta = rng.uniform(-np.pi / 2 + 1e-3, np.pi / 2 - 1e-3, 1000)
    psi = rng.uniform(-np.pi, np.pi, 1000)
    a = orientation_angles(orientation_matrix(phi, theta, psi))
    assert_allclose(a.somersault, phi, atol=1e-9)
    assert_allclose(a.tilt, theta, atol=1e-12)
    assert_allclose(a.twist, psi, atol=1e-9)
    assert not a.singular.any()
    # and matrix -> angles -> matrix for random rotations
    S = Rotation.random(500, random_state=2).as_matrix()
    b = orientation_angles(S)
    assert_allclose(orientation_matrix(b.somersault, b.tilt, b.twist), S, atol=1e-12)


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_gimbal_lock_is_flagged_and_the_matrix_kept(sign: float) -> None:
    S = orientation_matrix(
        [0.3, 0.3, 0.3], sign * np.array([np.pi / 2, np.pi / 2 - 1e-8, 1.0]), 0.5
    )
    a = orientation_angles(S)
    assert a.singular.tolist() == [True, True, False]
    assert_allclose(a.tilt[:2], sign * np.pi / 2, atol=1e-7)
    assert np.all(a.twist[:2] == 0.0)
    # only phi + psi (tilt +pi/2) or phi - psi (tilt -pi/2) is defined, and kept
    assert_allclose(a.somersault[0], 0.3 + sign * 0.5, atol=1e-12)
    assert_allclose(orientation_matrix(a.somersault, a.tilt, a.twist), S, atol=1e-7)
    assert a.cos_tilt[2] == pytest.approx(np.cos(1.0))


def test_segment_matrix_is_the_papers_product() -> None:
    # S_ac = R1(delta) R2(epsilon) R3(-psi), with Yeadon's element formulas
    d, e, p = 0.5, -0.4, 1.2
    S = segment_matrix(d, e, p)
    assert_allclose(S, _rot(0, -d) @ _rot(1, -e) @ _rot(2, p), atol=1e-15)
    assert_allclose(S[0, 2], -np.sin(e))
    assert_allclose(S[1, 2], np.sin(d) * np.cos(e))
    assert_allclose(S[2, 2], np.cos(d) * np.cos(e))
    assert_allclose(S[0, 1], -np.cos(e) * np.sin(p))
    a = segment_angles(S)
    assert_allclose([a.elevation, a.abduction, a.rotation], [d, e, p], atol=1e-12)
    lock = segment_angles(segment_matrix(0.2, np.pi / 2, 0.3))
    assert lock.singular and lock.rotation == 0.0
    assert_allclose(
        segment_matrix(lock.elevation, lock.abduction, 0.0),
        segment_matrix(0.2, np.pi / 2, 0.3),
        atol=1e-12,
    )


def test_limb_angles_from_joint_centres_known_answers() -> None:
    chest = np.eye(3)  # c1 lateral, c2 forward, c3 up
    shoulder = np.array([0.0, 0.0, 1400.0])
    # arm hanging, forearm forward: all angles zero
    a = segment_angles_from_joints(
        chest, shoulder, shoulder - _v(0, 0, 300), shoulder + _v(0, 250, -300)
    )
    assert_allclose([a.elevation, a.abduction, a.rotation], 0.0, atol=1e-15)
    # arm raised 90 deg forward in the sagittal plane (forearm up): elevation 90 deg
    elbow = shoulder + _v(0.0, 300.0, 0.0)
    a = segment_angles_from_joints(chest, shoulder, elbow, elbow + _v(0.0, 0.0, 250.0))
    assert_allclose(abs(a.elevation), np.pi / 2, atol=1e-12)
    assert_allclose([a.abduction, a.rotation], 0.0, atol=1e-12)
    # arm abducted sideways 30 deg, elbow flexed forward: abduction +-30 deg only
    down = np.array([np.sin(np.radians(30)), 0.0, -np.cos(np.radians(30))])
    elbow = shoulder + 300.0 * down
    a = segment_angles_from_joints(chest, shoulder, elbow, elbow + _v(0.0, 250.0, 0.0))
    assert_allclose(abs(a.abduction), np.radians(30), atol=1e-12)
    assert_allclose([a.elevation, a.rotation], 0.0, atol=1e-12)


def test_limb_angles_round_trip_through_joint_centres() -> None:
    rng = np.random.default_rng(3)
    n = 200
    d = rng.uniform(-3.0, 3.0, n)
    e = rng.uniform(-1.4, 1.4, n)
    p = rng.uniform(-3.0, 3.0, n)
    chest = Rotation.random(n, random_state=4).as_matrix()
    A = chest @ segment_matrix(d, e, p)  # limb axes in the world
    elbow = rng.uniform(-500, 500, (n, 3))
    shoulder = elbow + 300.0 * A[:, :, 2]
    wrist = elbow + 250.0 * A[:, :, 1]  # forearm along a2: elbow flexed 90 deg
    a = segment_angles_from_joints(chest, shoulder, elbow, wrist)
    assert_allclose(a.elevation, d, atol=1e-9)
    assert_allclose(a.abduction, e, atol=1e-9)
    assert_allclose(a.rotation, p, atol=1e-9)


def test_straight_limb_is_flagged_with_nan_angles() -> None:
    shoulder = np.array([[0.0, 0, 1400], [0.0, 0, 1400]])
    elbow = shoulder - [0.0, 0.0, 300.0]
    wrist = np.array([[0.0, 0.0, 850.0], [0.0, 200.0, 1100.0]])  # straight; bent
    a = segment_angles_from_joints(np.eye(3), shoulder, elbow, wrist)
    assert a.singular.tolist() == [True, False]
    assert np.isnan(a.rotation[0]) and np.isfinite(a.rotation[1])
    axes, straight = limb_axes(shoulder, elbow, wrist)
    assert straight.tolist() == [True, False]
    assert_allclose(np.linalg.det(axes[1]), 1.0)


def test_nan_frames_stay_nan_and_unflagged() -> None:
    S = np.stack([np.eye(3), np.full((3, 3), np.nan)])
    a = orientation_angles(S)
    assert np.isnan(a.tilt[1]) and not a.singular[1]
    assert a.tilt[0] == 0.0


@pytest.mark.parametrize(
    ("axes", "match"),
    [
        (np.eye(2), "shape"),
        (2.0 * np.eye(3), "orthonormal"),
        (np.diag([1.0, 1.0, -1.0]), "left-handed"),
        (np.full((3, 3), np.inf), "infinite"),
    ],
)
def test_bad_axes_raise(axes: np.ndarray, match: str) -> None:
    with pytest.raises(KinematicsError, match=match):
        orientation_angles(axes)
    with pytest.raises(KinematicsError, match=match):
        segment_angles(axes)


def test_bad_joint_centres_raise() -> None:
    p = np.zeros(3)
    with pytest.raises(KinematicsError, match="coincide"):
        limb_axes(p, p, [1.0, 0, 0])
    with pytest.raises(KinematicsError, match="shape"):
        limb_axes([0.0, 1.0], [0.0, 0.0], [1.0, 0.0])
    with pytest.raises(KinematicsError, match="broadcast"):
        limb_axes(np.zeros((2, 3)), np.zeros((3, 3)), np.zeros(3))


def test_docstring_example_runs() -> None:
    failures, tried = doctest.testmod(angles, optionflags=doctest.NORMALIZE_WHITESPACE)
    assert tried > 0 and failures == 0
