"""SPX conformance: the simulator in CI, a real device with ``--hw selspot=PORT``."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from spotlab.simulators import service
from spotlab.testing.pytest_plugin import hardware_ports
from spotlab.testing.selspot_conformance import SelspotConformance


@pytest.fixture(params=["pty", "sim-url"])
def selspot_port(request: pytest.FixtureRequest) -> Iterator[str]:
    hw = hardware_ports(request.config).get("selspot")
    if hw is not None:
        if request.param != "pty":
            pytest.skip("hardware run: one port only")
        yield hw
        return
    options = service.SelspotSimOptions(cameras=4, leds=32, seed=3)
    if request.param == "sim-url":
        yield service.url_for(options)
        return
    server = service.serve_pty(options)
    try:
        yield str(server.path)
    finally:
        server.stop()


class TestSelspotConformance(SelspotConformance):
    """Every test of the family's suite, against ``selspot_port``."""
