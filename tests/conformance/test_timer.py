"""TMR conformance: the simulator in CI, a real unit with ``--hw timer=PORT``."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from spotlab.simulators import service
from spotlab.testing.pytest_plugin import hardware_ports
from spotlab.testing.timer_conformance import TimerConformance


@pytest.fixture(params=["pty", "sim-url"])
def timer_port(request: pytest.FixtureRequest) -> Iterator[str]:
    hw = hardware_ports(request.config).get("timer")
    if hw is not None:
        if request.param != "pty":
            pytest.skip("hardware run: one port only")
        yield hw
        return
    options = service.TimerSimOptions(seed=3)
    if request.param == "sim-url":
        yield service.timer_url_for(options)
        return
    server = service.serve_timer_pty(options)
    try:
        yield str(server.path)
    finally:
        server.stop()


class TestTimerConformance(TimerConformance):
    """Every test of the family's suite, against ``timer_port``."""
