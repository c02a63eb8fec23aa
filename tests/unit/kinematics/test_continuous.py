"""continuous_angle (Yeadon's incremental rule) and align_angle."""

from __future__ import annotations

import doctest

import numpy as np
import pytest
from numpy.testing import assert_allclose

from spotlab.kinematics import KinematicsError, continuous
from spotlab.kinematics.continuous import align_angle, continuous_angle


def test_several_turns_are_followed() -> None:
    # a triple somersault with twist: angles far outside (-pi, pi]
    t = np.linspace(0.0, 1.0, 400)
    somersault = 3.0 * 2.0 * np.pi * t - 0.2
    twist = -1.5 * 2.0 * np.pi * t**2
    truth = np.stack([somersault, twist], axis=1)
    got = continuous_angle(np.sin(truth), np.cos(truth))
    assert_allclose(got, truth, atol=1e-12)


def test_initial_value_in_yeadons_range() -> None:
    # A0 in (-pi/2, 3pi/2]: an angle of -2.5 rad starts at 2 pi - 2.5
    got = continuous_angle(np.sin([-2.5, -2.4]), np.cos([-2.5, -2.4]))
    assert_allclose(got, [2.0 * np.pi - 2.5, 2.0 * np.pi - 2.4])
    # the edge the paper's arctan form gets wrong: sin 1, cos 0 is pi/2, not 3pi/2
    assert_allclose(continuous_angle([1.0], [0.0]), [np.pi / 2])
    assert_allclose(continuous_angle([0.0], [-1.0]), [np.pi])
    assert_allclose(continuous_angle([-1.0], [0.0]), [3.0 * np.pi / 2])


def test_each_step_is_within_pi_and_matches_the_loop_of_the_paper() -> None:
    rng = np.random.default_rng(1)
    a = np.cumsum(rng.uniform(-3.0, 3.0, 300))
    s, c = np.sin(a) * 2.0, np.cos(a) * 2.0  # any common scale
    got = continuous_angle(s, c)
    assert np.all(np.abs(np.diff(got)) < np.pi)
    # the paper's procedure, one sample at a time
    prev = np.arctan2(s[0], c[0])
    prev = prev + 2 * np.pi if prev <= -np.pi / 2 else prev
    ref = [prev]
    for k in range(1, a.size):
        sa, ca = s[k] / 2.0, c[k] / 2.0
        cb = ca * np.cos(prev) + sa * np.sin(prev)
        sb = sa * np.cos(prev) - ca * np.sin(prev)
        prev = prev + np.arctan2(sb, cb)
        ref.append(prev)
    assert_allclose(got, ref, atol=1e-9)
    # and the history is the true one up to whole turns
    assert_allclose(np.diff(got), np.diff(a), atol=1e-9)


def test_gaps_are_bridged_and_stay_nan() -> None:
    a = np.linspace(0.0, 10.0, 50)
    s, c = np.sin(a), np.cos(a)
    s[[0, 1, 20, 21, 22]] = np.nan
    got = continuous_angle(s, c)
    assert np.all(np.isnan(got[[0, 1, 20, 21, 22]]))
    ok = np.isfinite(got)
    assert_allclose(got[ok] - got[ok][0], a[ok] - a[ok][0], atol=1e-12)


def test_axis_and_reference() -> None:
    a = np.linspace(5.0, 8.0, 30)
    got = continuous_angle(np.sin(a)[None, :], np.cos(a)[None, :], axis=1, reference=6.0)
    assert_allclose(got[0], a, atol=1e-12)


def test_errors() -> None:
    with pytest.raises(KinematicsError, match="same shape"):
        continuous_angle([0.0, 1.0], [1.0])
    with pytest.raises(KinematicsError, match="both 0"):
        continuous_angle([0.0, 0.0], [1.0, 0.0])
    with pytest.raises(KinematicsError, match="NaN everywhere"):
        continuous_angle([np.nan], [np.nan])
    with pytest.raises(KinematicsError, match="infinite"):
        continuous_angle([np.inf], [1.0])


def test_align_angle() -> None:
    assert_allclose(align_angle([0.1 + 2 * np.pi, -6.0, np.pi], 0.0), [0.1, 2 * np.pi - 6.0, np.pi])
    assert_allclose(align_angle(-np.pi, 0.0), np.pi)  # the half-open interval
    assert_allclose(align_angle(0.0, 20.0), 6 * np.pi)


def test_docstring_example_runs() -> None:
    failures, tried = doctest.testmod(continuous, optionflags=doctest.NORMALIZE_WHITESPACE)
    assert tried > 0 and failures == 0
