"""WSX conformance: the simulated hub in CI, a real one with ``--hw wsx=SERIAL``
(``usb:SERIAL`` and ``wsxsim://HOST:PORT/SERIAL`` are taken as they are)."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from spotlab.simulators.wsx_service import WsxSimOptions, serve_wsx
from spotlab.testing.pytest_plugin import hardware_ports
from spotlab.testing.wsx_conformance import WsxConformance


@pytest.fixture(scope="module")
def wsx_port(request: pytest.FixtureRequest) -> Iterator[str]:
    hw = hardware_ports(request.config).get("wsx")
    if hw is not None:
        yield hw if ":" in hw else f"usb:{hw}"
        return
    server = serve_wsx(WsxSimOptions(sensors=2, markers=6, seed=2))
    try:
        yield server.address
    finally:
        server.stop()


class TestWsxConformance(WsxConformance):
    """Every test of the WSX suite against ``wsx_port``."""
