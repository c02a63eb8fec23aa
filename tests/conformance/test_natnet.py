"""NatNet conformance: the simulated Motive in CI, a real one with ``--hw natnet=HOST[:PORT]``.

Against the simulator the suite runs for NatNet 3.1 and 4.1, with a server that
forgets a silent client after 2 s (Motive's own time-out is longer), so that the
keep-alive test proves the driver's keep-alives within a short span.
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from spotlab.simulators.natnet import NatNetServer
from spotlab.simulators.natnet_scene import NatNetScene
from spotlab.testing.natnet_conformance import NatNetConformance
from spotlab.testing.pytest_plugin import hardware_ports


@pytest.fixture(params=[(4, 1), (3, 1)], ids=["natnet4.1", "natnet3.1"])
def natnet_address(request: pytest.FixtureRequest) -> Iterator[str]:
    hw = hardware_ports(request.config).get("natnet")
    if hw is not None:
        if request.param != (4, 1):
            pytest.skip("a real server speaks its own version: run once")
        yield hw
        return
    if request.instance is not None:  # the simulator forgets a silent client after 2 s
        request.instance.keepalive_span_s = 4.0
    scene = NatNetScene(markers=40, cameras=4, rate_hz=120.0, seed=1)
    with NatNetServer(scene, version=request.param, client_timeout_s=2.0) as server:
        yield server.address


class TestNatNetConformance(NatNetConformance):
    """Every test of the NatNet suite against ``natnet_address`` (keep-alive: 12 s with
    ``--hw``, 4 s against the simulator)."""
