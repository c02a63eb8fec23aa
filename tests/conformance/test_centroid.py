"""CEN conformance: the simulator in CI, a real hub with ``--hw centroid=PORT``."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from spotlab.simulators.centroid_service import (
    CentroidSimOptions,
    centroid_url_for,
    serve_centroid_pty,
)
from spotlab.testing.centroid_conformance import CentroidConformance
from spotlab.testing.pytest_plugin import hardware_ports


@pytest.fixture(params=["pty", "sim-url"])
def centroid_port(request: pytest.FixtureRequest) -> Iterator[str]:
    hw = hardware_ports(request.config).get("centroid")
    if hw is not None:
        if request.param != "pty":
            pytest.skip("hardware run: one port only")
        yield hw
        return
    options = CentroidSimOptions(cameras=4, markers=20, seed=5)
    if request.param == "sim-url":
        yield centroid_url_for(options)
        return
    server = serve_centroid_pty(options)
    try:
        yield str(server.path)
    finally:
        server.stop()


class TestCentroidConformance(CentroidConformance):
    """Every test of the family's suite, against ``centroid_port``."""
