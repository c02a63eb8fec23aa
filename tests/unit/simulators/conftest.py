"""Fixtures of the simulator tests: small deterministic scenes and devices in simulated time."""

from __future__ import annotations

from collections.abc import Callable

import pytest
from _simwire import T0, Host

from spotlab.simulators.clock import DeviceClock
from spotlab.simulators.faults import FaultInjector
from spotlab.simulators.motions import make_motion
from spotlab.simulators.scene import Scene, ring_rig
from spotlab.simulators.selspot import SelspotDevice


@pytest.fixture
def make_device() -> Callable[..., SelspotDevice]:
    """Factory of devices powered up at T0 (simulated ns), 4 cameras, 32 wand/reference LEDs."""

    def make(
        cameras: int = 4,
        leds: int = 32,
        faults: str = "",
        rate: float = 0.0,
        seed: int = 1,
        clock: DeviceClock | None = None,
        scene: Scene | None = None,
        **kwargs: object,
    ) -> SelspotDevice:
        scene = scene or Scene(make_motion("wand", leds, seed), ring_rig(cameras))
        clock = clock or DeviceClock(epoch_ns=T0)
        return SelspotDevice(
            scene,
            clock,
            FaultInjector(faults, rate=rate, seed=seed),
            seed=seed,
            now_ns=T0,
            **kwargs,
        )

    return make


@pytest.fixture
def host(make_device: Callable[..., SelspotDevice]) -> Host:
    """A host driving a default device; the power-up banner already read."""
    h = Host(make_device())
    h.wait(20_000_000)
    h.buf.clear()
    return h
