"""PSD physics: centroid of all light, fall-off, noise, quantisation, flags, occlusion."""

from __future__ import annotations

import numpy as np
import pytest

from spotlab.simulators import wire
from spotlab.simulators.motions import StaticMarkers
from spotlab.simulators.psd import PsdModel, PsdReading
from spotlab.simulators.scene import (
    Ambient,
    Mirror,
    OcclusionInterval,
    PsdCamera,
    Scene,
    SphereOccluder,
)

FOCAL = 2000.0
EYE = (0.0, -3000.0, 1000.0)  # looks horizontally along +y at height 1 m


def camera(**kw: float) -> PsdCamera:
    return PsdCamera.look_at(EYE, (0.0, 0.0, 1000.0), focal=FOCAL, **kw)  # type: ignore[arg-type]


def read(
    points: list[tuple[float, float, float]] | np.ndarray,
    *,
    current_ma: float = 32.0,
    model: PsdModel | None = None,
    mirrors: tuple[Mirror, ...] = (),
    occluders: tuple[SphereOccluder, ...] = (),
    intervals: tuple[OcclusionInterval, ...] = (),
    ambient: Ambient | None = None,
    dark: bool = True,
    t: float = 0.0,
    seed: int = 0,
) -> PsdReading:
    pts = np.asarray(points, dtype=float).reshape(-1, 3)
    scene = Scene(
        StaticMarkers(pts),
        [camera()],
        mirrors=mirrors,
        occluders=occluders,
        intervals=intervals,
        ambient=ambient or Ambient(),
    )
    ids = np.arange(len(pts))
    times = np.full(len(pts), t)
    X = scene.positions(times, ids)
    spots = scene.spots(X, times, ids)
    amb = scene.ambient_level(times)
    m = model or PsdModel(electrode_noise=0.0, pincushion=0.0)
    return m.measure(
        spots,
        np.full(len(pts), current_ma),
        amb,
        amb if dark else None,
        np.random.default_rng(seed),
        scene.ambient.centroid,
    )


def test_led_on_the_axis_reads_the_centre() -> None:
    r = read([(0, 0, 1000)])
    assert (r.x[0, 0], r.y[0, 0]) == (2048, 2048)
    assert r.flags[0, 0] == wire.FLAG_VALID
    # gain 42 per mA at 1 m: 32 mA at 3 m on axis -> 149.3
    assert r.intensity[0, 0] == round(42 * 32 / 9)


def test_power_falls_with_distance_squared_and_off_axis_angle() -> None:
    near, far = read([(0, 0, 1000), (0, 3000, 1000)]).power[:, 0]
    assert near / far == pytest.approx(4.0)
    off = read([(0, 0, 1000), (1500, 0, 1000)]).power[:, 0]
    cos = 3000 / np.hypot(3000, 1500)
    d2 = (3000**2 + 1500**2) / 3000**2
    assert off[1] / off[0] == pytest.approx(cos**4 / d2)


def test_reflection_biases_the_centroid_towards_the_mirror_image() -> None:
    led = (0.0, 0.0, 1000.0)
    floor = Mirror((0, 0, 0), (0, 0, 1), reflectance=0.3)
    plain = read([led])
    mirrored = read([led], mirrors=(floor,))
    # Independent expectation: the mirror image (0, 0, -1000) seen from the camera.
    down = 2000.0 / 3000.0  # tan of the angle below the axis
    v_image = 2048 + FOCAL * down
    d_direct, d_image = 3000.0, np.hypot(3000.0, 2000.0)
    p_direct = 42 * 32 / (d_direct / 1000) ** 2
    p_image = 0.3 * 42 * 32 * (3000 / d_image) ** 4 / (d_image / 1000) ** 2
    expected_y = (p_direct * 2048 + p_image * v_image) / (p_direct + p_image)
    assert plain.y[0, 0] == 2048
    assert mirrored.y[0, 0] == round(expected_y)
    assert mirrored.y[0, 0] > 2048 + 50  # a bias, not a second spot
    assert mirrored.x[0, 0] == 2048  # the image is straight below
    assert mirrored.intensity[0, 0] == round(p_direct + p_image)


def test_reflection_seen_when_the_direct_path_is_blocked() -> None:
    led = (0.0, 0.0, 1000.0)
    floor = Mirror((0, 0, 0), (0, 0, 1), reflectance=0.5)
    blocker = SphereOccluder((0.0, -1500.0, 1000.0), 100.0)  # on the direct line only
    r = read([led], mirrors=(floor,), occluders=(blocker,))
    assert r.flags[0, 0] & wire.FLAG_VALID
    assert r.y[0, 0] == round(2048 + FOCAL * 2000 / 3000)  # only the image remains


def test_noise_grows_as_intensity_falls() -> None:
    model = PsdModel(electrode_noise=0.5, pincushion=0.0)
    n = 4000
    pts = np.tile([[300.0, 0.0, 1000.0]], (n, 1))
    bright = read(pts, current_ma=40.0, model=model, seed=1)
    dim = read(pts, current_ma=10.0, model=model, seed=2)
    assert np.all(bright.flags & wire.FLAG_VALID) and np.all(dim.flags & wire.FLAG_VALID)
    sd_bright, sd_dim = bright.x[:, 0].std(), dim.x[:, 0].std()
    ratio = bright.intensity.mean() / dim.intensity.mean()
    assert ratio == pytest.approx(4.0, rel=0.02)
    assert sd_dim / sd_bright == pytest.approx(ratio, rel=0.15)
    # The mean stays on the true position: noise, not bias.
    assert dim.x[:, 0].mean() == pytest.approx(2048 + FOCAL * 0.1, abs=1.0)


@pytest.mark.parametrize("u_offset", [0.4, 0.6, 10.49, 10.51])
def test_coordinates_are_quantised_to_counts(u_offset: float) -> None:
    x_mm = u_offset / FOCAL * 3000.0
    r = read([(x_mm, 0.0, 1000.0)])
    assert r.x.dtype == np.uint16
    assert r.x[0, 0] == round(2048 + u_offset)


def test_pincushion_pushes_outwards_more_at_the_edge() -> None:
    model = PsdModel(electrode_noise=0.0, pincushion=0.02)
    r = read([(300.0, 0, 1000.0), (2700.0, 0, 1000.0)], model=model)
    true_u = 2048 + FOCAL * np.array([0.1, 0.9])
    err = r.x[:, 0] - true_u
    assert 0 <= err[0] < 1.5
    p = 0.9 * FOCAL / 2047
    assert err[1] == pytest.approx(2047 * p * 0.02 * p * p, abs=1.0)


def test_saturation_is_flagged_and_pulls_towards_the_centre() -> None:
    led = (900.0, 0.0, 1000.0)  # 600 counts right of the centre
    ok = read([led], current_ma=32.0)
    hot = read([led], current_ma=255 / 4 * 4)
    assert not ok.flags[0, 0] & wire.FLAG_SATURATED
    assert hot.flags[0, 0] & wire.FLAG_SATURATED and hot.flags[0, 0] & wire.FLAG_VALID
    assert hot.intensity[0, 0] <= 255
    assert abs(int(hot.x[0, 0]) - 2048) < abs(int(ok.x[0, 0]) - 2048)


def test_low_signal_is_invalid_with_fff() -> None:
    r = read([(0, 30_000, 1000)], current_ma=2.0)
    assert (r.x[0, 0], r.y[0, 0]) == (0xFFF, 0xFFF)
    assert r.flags[0, 0] == wire.FLAG_LOW_SIGNAL
    assert r.intensity[0, 0] < 8


def test_not_seen_cases_are_invalid() -> None:
    r = read(
        [
            (0, -4000, 1000),  # behind the camera
            (5000, 0, 1000),  # off the detector
            (0, 0, 1000),  # hidden by the occlusion interval
            (0, 1000, 1000),  # behind the sphere
            (np.nan, np.nan, np.nan),  # missing in the motion
        ],
        intervals=(OcclusionInterval(led=2, t0=-1.0, t1=1.0),),
        occluders=(SphereOccluder((0.0, 500.0, 1000.0), 200.0),),
    )
    assert np.all(r.x == 0xFFF) and np.all(r.y == 0xFFF)
    assert np.all((r.flags & wire.FLAG_VALID) == 0)


def test_occlusion_interval_ends() -> None:
    iv = (OcclusionInterval(led=0, t0=1.0, t1=2.0, camera=0),)
    assert read([(0, 0, 1000)], intervals=iv, t=0.5).flags[0, 0] & wire.FLAG_VALID
    assert not read([(0, 0, 1000)], intervals=iv, t=1.5).flags[0, 0] & wire.FLAG_VALID
    assert read([(0, 0, 1000)], intervals=iv, t=2.0).flags[0, 0] & wire.FLAG_VALID


def test_near_edge_flag() -> None:
    inner = 0.89 * 2047 / FOCAL * 3000
    outer = 0.91 * 2047 / FOCAL * 3000
    r = read([(inner, 0, 1000), (outer, 0, 1000)])
    assert not r.flags[0, 0] & wire.FLAG_NEAR_EDGE
    assert r.flags[1, 0] & wire.FLAG_NEAR_EDGE and r.flags[1, 0] & wire.FLAG_VALID


def test_ambient_light_and_background_differencing() -> None:
    amb = Ambient(level=80.0, flicker=0.0, centroid=(3000.0, 2048.0))
    led = [(0.0, 0.0, 1000.0)]
    differenced = read(led, ambient=amb, dark=True)
    raw = read(led, ambient=amb, dark=False)
    assert differenced.flags[0, 0] & wire.FLAG_AMBIENT_HIGH
    assert differenced.x[0, 0] == 2048  # a steady ambient is removed exactly
    expected = (149.33 * 2048 + 80 * 3000) / (149.33 + 80)
    assert raw.x[0, 0] == pytest.approx(expected, abs=1)  # without it, it biases the centroid
    assert raw.intensity[0, 0] == pytest.approx(149.33 + 80, abs=1)
    quiet = read(led, ambient=Ambient(level=30.0))
    assert not quiet.flags[0, 0] & wire.FLAG_AMBIENT_HIGH
