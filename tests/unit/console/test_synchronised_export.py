"""Synchronised reconstruction of several image streams: synthetic streams of two
4-camera systems with their own frame phases, clock rates and LED slots, seeing the same
fast-moving markers."""

from __future__ import annotations

import numpy as np
import pytest

from spotlab.console.errors import CommandError
from spotlab.core.streams import StreamSpec
from spotlab.geometry import Rig
from spotlab.processing.marker_observations import MarkerObservations
from spotlab.processing.synchronised_export import (
    ImageStream,
    check_rig,
    synchronise_observations,
)
from spotlab.processing.trajectories import reconstruct
from spotlab.simulators.rigs import ring_rig

RIG = ring_rig(8, distortion=False)
RATE = 100.0
SLOT = 1e-3  # s per LED slot: marker k sampled (k + 1/2) ms after its frame's start
M = 4


def truth(t: np.ndarray) -> np.ndarray:
    """Markers on a 500 mm circle at 10 rad/s (5 m/s), phases apart, at times (T,) (every
    marker) or (F, M) (marker k at t[:, k]) -> (T or F, M, 3) mm."""
    t = np.asarray(t)
    t = t[:, None] if t.ndim == 1 else t
    a = 10.0 * t + np.arange(M) * np.pi / 2
    return np.stack([500 * np.cos(a), 500 * np.sin(a), 900 + 100 * np.sin(a / 3)], axis=-1)


def stream(name: str, cams: slice, start: float, clock_rate: float, n: int) -> ImageStream:
    """Frames every 1/RATE device s from session time ``start``; marker k seen at its slot."""
    spec = StreamSpec(name, "image2d", 4, M, RATE, 1e6, slot_period_s=SLOT)
    frame_t = start + np.arange(n) / RATE * clock_rate
    sample_t = frame_t[:, None] + (np.arange(M) + 0.5) * SLOT * clock_rate  # (F, M)
    X = truth(sample_t)  # (F, M, 3)
    uv = Rig(list(RIG)[cams]).project(X)  # (C, F, M, 2)
    return ImageStream(spec, np.arange(n), frame_t, uv.transpose(1, 2, 0, 3), clock_rate)


def two_streams() -> list[ImageStream]:
    return [
        stream("selspot0", slice(0, 4), 0.0013, 1 + 200e-6, 150),
        stream("selspot1", slice(4, 8), 0.0061, 1 - 150e-6, 150),
    ]


def errors(streams: list[ImageStream], **kw: object) -> tuple[np.ndarray, object]:
    obs = synchronise_observations(streams, **kw)  # type: ignore[arg-type]
    result = reconstruct(RIG, MarkerObservations(obs.uv, obs.rate_hz))
    err = np.linalg.norm(result.trial.points - truth(obs.times), axis=-1)
    return err, obs


def test_two_systems_resampled_at_common_instants_match_the_truth() -> None:
    err, obs = errors(two_streams())
    seen = np.isfinite(err)
    assert seen.mean() > 0.95
    assert np.max(err[seen]) < 0.05  # mm: spline error at 100 Hz of a 5 m/s circle
    # instants on the session grid: frame f at (f - 1) / rate, first after both began
    assert np.allclose(obs.times, (obs.first_frame - 1 + np.arange(obs.times.size)) / RATE)
    assert obs.times[0] >= 0.0061 + 3.5 * SLOT and obs.first_frame == 2
    assert obs.cameras == {"selspot0": 4, "selspot1": 4}
    assert obs.facts["selspot0"]["lost_frames"] == 0


def test_without_slot_correction_fast_markers_lag_by_speed_times_slot() -> None:
    err, _ = errors(two_streams(), slot_correction=False)
    seen = np.isfinite(err)
    # marker k lags (k + 1/2) ms at 5 m/s: 2.5 .. 17.5 mm (a little less after triangulation)
    per_marker = np.nanmedian(err, axis=0)
    assert np.all(per_marker > 2.0) and per_marker[-1] > 12.0
    assert seen.mean() > 0.95


def test_a_gap_in_one_stream_leaves_the_other_cameras_and_never_bridges_it() -> None:
    a, b = two_streams()
    keep = np.r_[0:50, 60:150]  # 10 frames lost in system A
    a = ImageStream(a.spec, a.seq[keep], a.time_s[keep], a.uv[keep], a.clock_rate)
    obs = synchronise_observations([a, b])
    in_gap = (obs.times > a.time_s[49] + 0.005) & (obs.times < a.time_s[50] - 0.001)
    assert in_gap.sum() >= 8
    assert np.all(np.isnan(obs.uv[in_gap, :4]))  # system A's cameras: nothing in the gap
    assert np.all(np.isfinite(obs.uv[in_gap, 4:]))
    assert obs.facts["selspot0"]["lost_frames"] == 10
    # system B's four cameras still reconstruct every marker in A's gap
    result = reconstruct(RIG, MarkerObservations(obs.uv, obs.rate_hz))
    err = np.linalg.norm(result.trial.points[in_gap] - truth(obs.times[in_gap]), axis=-1)
    assert np.max(err) < 0.05


def test_missing_readings_stay_missing_and_markers_may_differ_in_count() -> None:
    a, b = two_streams()
    a.uv[70:75, 1, :] = np.nan  # marker 1 unseen by system A for 5 frames
    spec = StreamSpec("selspot1", "image2d", 4, 2, RATE, 1e6, slot_period_s=SLOT)
    b = ImageStream(spec, b.seq, b.time_s, np.ascontiguousarray(b.uv[:, :2]), b.clock_rate)
    obs = synchronise_observations([a, b], rate_hz=200.0)
    assert obs.rate_hz == 200.0 and obs.uv.shape[1:] == (8, M, 2)
    assert np.all(np.isnan(obs.uv[:, 4:, 2:]))  # markers system B does not have
    gap = (obs.times > a.time_s[69]) & (obs.times < a.time_s[75])
    assert np.all(np.isnan(obs.uv[gap, :4, 1]))
    assert np.all(np.isfinite(obs.uv[gap, :4, 0]))


def test_bad_inputs_are_one_clear_error() -> None:
    a, b = two_streams()
    with pytest.raises(CommandError, match=r"8 .*selspot0: 4, selspot1: 4"):
        check_rig(Rig(list(RIG)[:6]), {"selspot0": 4, "selspot1": 4})
    with pytest.raises(CommandError, match="no image2d stream"):
        synchronise_observations([])
    with pytest.raises(CommandError, match="positive"):
        synchronise_observations([a, b], rate_hz=-5.0)
    late = ImageStream(b.spec, b.seq, b.time_s + 10.0, b.uv, b.clock_rate)
    with pytest.raises(CommandError, match="overlap"):
        synchronise_observations([a, late])
    early = ImageStream(a.spec, a.seq, a.time_s - 5.0, a.uv, a.clock_rate)
    with pytest.raises(CommandError, match="after session time 0"):
        synchronise_observations([early])
