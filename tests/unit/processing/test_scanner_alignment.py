"""Two scanners in one frame from a shared static L-frame (simulated units at two poses)."""

from __future__ import annotations

import numpy as np
import pytest

from spotlab.drivers.coda import CodaDecoder
from spotlab.processing.errors import InputError
from spotlab.processing.scanner_alignment import (
    align_pairs,
    align_scanners,
    align_still,
    points_at,
    still_markers,
)
from spotlab.processing.scanner_trajectories import ScannerRecording, scanner_points
from spotlab.simulators import coda_scene as scene
from spotlab.simulators.clock import DeviceClock
from spotlab.simulators.coda import CodaConfig, CodaDevice, CodaFaults, CodaStream
from spotlab.simulators.coda_wire import id_colour

TABLE = [1, 2, 3, 4, 50, 51, 52, 53]
LABELS = [id_colour(i) for i in TABLE]
REFERENCE = [id_colour(i) for i in scene.REFERENCE]
RATE = 200.0


def _unit(pose: scene.Pose, seed: int, frames: int = 300) -> ScannerRecording:
    quiet = CodaFaults(colour=0.0, ghost=0.0, occlusion=0.0)
    device = CodaDevice(
        DeviceClock(epoch_ns=0), scene_markers=4, fault_rates=quiet, pose=pose,
        reference=True, seed=seed,
    )  # fmt: skip
    stream = CodaStream(device, CodaConfig(200_000, 3, TABLE), 7_000_000 * seed, 0)
    data = b"".join(stream.encode(stream.take(), 0, 0x10) for _ in range(frames))
    block = CodaDecoder(tuple(TABLE), "BOTH").feed(data, 0)
    m = len(TABLE)
    return ScannerRecording(
        block.data[:, :m, 0, :], block.flags[:, :m, 0], block.ticks.astype(np.float64),
        RATE, 1000.0, LABELS, f"unit{seed}",
    )  # fmt: skip


def test_the_second_unit_lands_in_the_first_units_frame() -> None:
    a = _unit(scene.Pose(), 1)
    b = _unit(scene.Pose(15.0, (800.0, 0.0, 0.0)), 2)
    pa, pb = scanner_points(a), scanner_points(b)
    assert np.isfinite(pb).all(axis=-1).mean() > 0.95  # B sees every marker
    alignment = align_scanners(pa, LABELS, pb, LABELS, REFERENCE)
    assert alignment.rms < 0.5 and len(alignment.labels) == 4
    # Unit A stands at the world origin: its frame is the world's.
    assert np.allclose(alignment.t, [800.0, 0.0, 0.0], atol=2.0)
    yaw = np.degrees(np.arctan2(alignment.R[1, 0], alignment.R[0, 0]))
    assert yaw == pytest.approx(15.0, abs=0.05)
    # B's moving markers, carried into A's frame, at their true world positions.
    at_s = (b.ticks_us + 0.4e6 / RATE) / 1e6
    truth = scene.marker_positions(np.array(TABLE[:4])[None, :], at_s[:, None])
    err = np.linalg.norm(alignment.apply(pb[:, :4]) - truth, axis=-1)
    assert np.nanmedian(err) < 1.5 and np.nanmax(err) < 6.0


def test_too_few_shared_reference_markers_is_one_clear_error() -> None:
    a = _unit(scene.Pose(), 1, frames=20)
    pa = scanner_points(a)
    with pytest.raises(InputError, match="not seen by both: WY, WG"):
        align_scanners(pa, LABELS, pa[:, :6], LABELS[:6], REFERENCE)


def test_still_markers_and_simultaneous_pairs_give_the_same_motion() -> None:
    a = _unit(scene.Pose(), 1, frames=120)
    b = _unit(scene.Pose(15.0, (800.0, 0.0, 0.0)), 2, frames=120)
    pa, pb = scanner_points(a), scanner_points(b)
    still = still_markers(pa, pb, LABELS)
    assert [LABELS[i] for i in still] == REFERENCE
    fit = align_still(pa, pb, LABELS, still)
    assert fit.method == "still" and fit.rms < 0.2
    # The moving markers at common instants (both units on one clock here: B's scans
    # interpolated at A's mid-sweeps) give the same motion.
    ta = (a.ticks_us + 0.4e6 / RATE) / 1e6
    tb = (b.ticks_us + 0.4e6 / RATE) / 1e6
    here = points_at(tb, pb, ta, 1 / RATE)
    pairs = align_pairs(pa[:, :4], here[:, :4], LABELS[:4])
    assert pairs.method == "pairs" and pairs.pairs > 300 and pairs.rms < 1.0
    assert np.allclose(pairs.t, fit.t, atol=2.0) and np.allclose(pairs.R, fit.R, atol=1e-3)
    with pytest.raises(InputError, match="seen by both: 2 of 4"):
        align_pairs(pa[:, :4], np.where(np.arange(4)[None, :, None] < 2, here[:, :4], np.nan),
                    LABELS[:4])  # fmt: skip


def test_points_between_two_scans_in_a_row_only() -> None:
    t = np.array([0.0, 1.0, 2.0, 4.0])
    p = np.arange(4, dtype=np.float64)[:, None, None] * np.ones((1, 1, 3))
    out = points_at(t, p, np.array([0.5, 2.5, 3.5, 5.0]), 1.0)
    assert out[0, 0, 0] == 0.5 and np.isnan(out[1:]).all()  # a lost scan, the end
