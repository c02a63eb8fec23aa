"""Options, URLs and device building for the command line and the tests."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from _simwire import MS, Host, cmd

from spotlab.simulators.motions import CallableMotion, Concat
from spotlab.simulators.service import (
    SelspotSimOptions,
    build_device,
    build_scene,
    options_from_url,
    url_for,
)


def test_url_round_trip(tmp_path: Path) -> None:
    options = SelspotSimOptions(
        cameras=4,
        leds=32,
        rate_hz=200.0,
        seed=7,
        faults="bitflip@1.5,overflow@5:3,disconnect@7:0.5",
        truth=tmp_path / "truth.csv",
        clock_drift_ppm=-20.0,
        clock_jitter_s=1e-5,
        motion="gait",
    )
    url = url_for(options)
    assert url.startswith("sim://selspot?cameras=4&leds=32&rate=200.0&seed=7&")
    assert "faults=bitflip@1.5,overflow@5:3,disconnect@7:0.5" in url
    assert options_from_url(url) == options
    assert url_for(SelspotSimOptions()) == "sim://selspot"


def test_url_short_and_long_names() -> None:
    a = options_from_url("sim://selspot?rate=50&clock_offset=2.5&clock_drift=3")
    b = options_from_url("sim://selspot?rate_hz=50&clock_offset_s=2.5&clock_drift_ppm=3")
    assert a == b and a.rate_hz == 50.0 and a.clock_offset_s == 2.5


@pytest.mark.parametrize(
    ("url", "message"),
    [
        ("sim://coda?x=1", "not a simulated selspot"),
        ("sim://selspot?cams=2", "unknown option"),
        ("sim://selspot?cameras=two", "not a valid int"),
        ("sim://selspot?leds=0", "leds"),
        ("sim://selspot?rate=0.5", "rate"),
        ("sim://selspot?motion=/no/such.c3d", "motion"),
    ],
)
def test_bad_urls(url: str, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        options_from_url(url)


def test_build_scene_follows_the_options() -> None:
    scene = build_scene(SelspotSimOptions(cameras=3, leds=10, floor_reflectance=0.0, ambient=5.0))
    assert scene.n_cameras == 3 and scene.n_leds == 10 and not scene.mirrors
    assert isinstance(scene.motion, Concat)
    assert scene.ambient_level(np.array([0.0])).shape == (1, 3)


def test_build_device_writes_truth_and_fault_log(tmp_path: Path) -> None:
    options = SelspotSimOptions(
        cameras=2,
        leds=4,
        rate_hz=200.0,
        truth=tmp_path / "t.csv",
        fault_log=tmp_path / "f.json",
        faults="duplicate@0.1",
    )
    h = Host(build_device(options, now_ns=10**12))
    h.wait(20 * MS)
    assert h.ask("RATE:1") == "ERROR23"
    h.configure(2, 4, 200_000)  # the default rate of these options is 200 Hz
    assert h.ask("INIT:") == "OKAY"
    h.send(cmd("LEDT:00800180"), baud=2_000_000)
    h.send(cmd("START:"), baud=2_000_000)
    h.wait(300 * MS)
    h.dev.close(h.t)
    rows = (tmp_path / "t.csv").read_text().splitlines()
    assert 55 <= len(rows) - 1 <= 61  # 200 Hz after INIT: the options' default rate
    log = json.loads((tmp_path / "f.json").read_text())
    assert log["faults"][0]["kind"] == "duplicate" and log["totals"]["duplicated_frames"] == 1


def test_callable_motion() -> None:
    def circle(t: np.ndarray) -> np.ndarray:
        return np.stack([np.cos(t), np.sin(t), np.ones_like(t)], axis=-1)[:, None, :] * [
            1000,
            1000,
            900,
        ]

    m = CallableMotion(circle, 1)
    np.testing.assert_allclose(m.positions(np.pi / 2)[0], [0, 1000, 900], atol=1e-9)
