"""Slot skew: a marker moving at 5 m/s, SELSPOT-style time multiplexing, with and without
slot correction, against the truth at the frame instants.

The rig fires 128 LEDs in 100 us slots at 75 Hz ((128 + 1) x 100 us fits 1/75 s,
docs/protocols/selspot.md timing check); every camera reads LED k at frame time +
(k + 1/2) x slot (selspot.md, "Timing"; simulators/spx_stream.py samples the scene
there). All cameras see LED k at the same instant, so its triangulated point is right
but belongs to the slot time: without correction, resampled at the frame instant, it is
late by (k + 1/2) x slot, a bias of v (k + 1/2) slot along the path (32 mm for k = 63 at
5 m/s). With correction the bias must vanish to the noise level.
"""

from __future__ import annotations

import numpy as np
import pytest

from spotlab.acquisition.synchroniser import StreamInput, Synchroniser
from spotlab.core import StreamSpec
from spotlab.reconstruction import triangulate
from spotlab.simulators.rigs import ring_rig

RATE_HZ = 75.0
SLOT_S = 100e-6
N_LEDS = 128
SPEED_MM_S = 5000.0
RADIUS_MM = 500.0
OMEGA = SPEED_MM_S / RADIUS_MM  # rad/s
NOISE_PX = 0.2


def path(t: np.ndarray) -> np.ndarray:
    """Centre of the LED cluster on a horizontal circle at 5 m/s, mm, shape (..., 3)."""
    a = OMEGA * t
    return np.stack([RADIUS_MM * np.cos(a), RADIUS_MM * np.sin(a), 900.0 + 0.0 * a], axis=-1)


def tangent(t: np.ndarray) -> np.ndarray:
    """Unit direction of motion, shape (..., 3)."""
    a = OMEGA * t
    return np.stack([-np.sin(a), np.cos(a), 0.0 * a], axis=-1)


def simulate() -> dict[str, np.ndarray]:
    """Errors of the reconstruction at the frame instants, with and without correction."""
    rng = np.random.default_rng(5)
    rig = ring_rig(4)
    # LEDs on a rigid cluster translating along the path (same velocity for all).
    cluster = rng.uniform(-60.0, 60.0, size=(N_LEDS, 3))
    drift = 1.0 + 200e-6  # the device clock runs 200 ppm fast against session time
    frame_times = 0.37 + np.arange(80) / RATE_HZ * drift
    offsets = (np.arange(N_LEDS) + 0.5) * SLOT_S * drift
    sample_t = frame_times[:, None] + offsets[None, :]  # (F, M)
    X = path(sample_t) + cluster[None, :, :]  # (F, M, 3) where each LED really was
    uv = rig.project(X)  # (C, F, M, 2)
    uv = uv + rng.normal(0.0, NOISE_PX, size=uv.shape)
    data = np.moveaxis(uv, 0, 2)  # (F, M, C, 2) as a frame block holds it
    spec = StreamSpec(
        "selspot0",
        "image2d",
        4,
        N_LEDS,
        RATE_HZ,
        1e6,
        slot_period_s=SLOT_S,
        values=("x", "y"),
        units=("px", "px"),
    )
    stream = StreamInput(spec, np.arange(80), frame_times, data, clock_rate=drift)
    instants = frame_times[1:-1]  # the frame instants (the first precedes every LED)
    out = {}
    for corrected in (True, False):
        res = Synchroniser([stream], slot_correction=corrected).resample(instants)
        uv_t = np.moveaxis(res.streams["selspot0"].values, 2, 0)  # (C, T, M, 2)
        assert np.all(res.streams["selspot0"].valid)
        out[corrected] = triangulate(rig, uv_t) - (path(instants)[:, None, :] + cluster)
    return {
        "with": out[True],
        "without": out[False],
        "direction": tangent(instants),
        "offsets": offsets,
        "raw_error": triangulate(rig, uv) - X,  # each LED at its own slot time
    }


@pytest.fixture(scope="module")
def session() -> dict[str, np.ndarray]:
    return simulate()


def along(err: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """Error along the direction of motion, (T, M) mm."""
    return np.einsum("tmk,tk->tm", err, direction)


def test_noise_level_of_the_rig(session: dict[str, np.ndarray]) -> None:
    rms = float(np.sqrt(np.mean(np.sum(session["raw_error"] ** 2, axis=-1))))
    assert 0.1 < rms < 2.0  # mm: 0.2 px at 4 m through 4 cameras


def test_with_slot_correction_no_bias_left(session: dict[str, np.ndarray]) -> None:
    a = along(session["with"], session["direction"])  # (T, M)
    per_led = a.mean(axis=0)
    noise = a.std(axis=0) / np.sqrt(a.shape[0])
    assert np.all(np.abs(per_led) < 5 * noise + 0.05)
    assert abs(float(a.mean())) < 0.05  # mm, over every LED and frame
    rms = float(np.sqrt(np.mean(np.sum(session["with"] ** 2, axis=-1))))
    raw = float(np.sqrt(np.mean(np.sum(session["raw_error"] ** 2, axis=-1))))
    assert rms < 1.2 * raw  # the interpolation adds next to nothing to the noise


def test_without_slot_correction_bias_is_speed_times_slot_offset(
    session: dict[str, np.ndarray],
) -> None:
    a = along(session["without"], session["direction"]).mean(axis=0)  # (M,)
    want = SPEED_MM_S * session["offsets"]  # v (k + 1/2) slot, mm
    assert want[63] == pytest.approx(31.76, abs=0.01)
    # The chord of the circle is a little shorter than the arc: cos(w dt / 2) <= 0.2 %.
    np.testing.assert_allclose(a, want, rtol=0.005, atol=0.2)
    slope = np.polyfit(np.arange(N_LEDS), a, 1)[0]
    assert slope == pytest.approx(SPEED_MM_S * SLOT_S, rel=0.01)  # 0.5 mm per LED
