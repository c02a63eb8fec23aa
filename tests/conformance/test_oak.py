"""OAK conformance: fake boards in CI, real boards with ``--hw oak=MXID[,MXID...]``."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from spotlab.drivers.oak import CameraSettings, OakDriver
from spotlab.simulators.motions import reference_markers
from spotlab.simulators.oak import FakeOakDevice, oak_rig
from spotlab.testing.oak_conformance import OakConformance
from spotlab.testing.pytest_plugin import hardware_ports


@pytest.fixture
def oak_driver(request: pytest.FixtureRequest) -> Iterator[OakDriver]:
    hw = hardware_ports(request.config).get("oak")
    if hw is not None:
        pytest.importorskip("depthai", reason="the oak extra is not installed")
        # One board runs as FSIN master, so the suite checks its sensors' getFsync too.
        settings = CameraSettings(fps=60.0, exposure_us=300, sync="master")
        driver = OakDriver(hw, settings=settings)
    else:
        rig = oak_rig(4, seed=1)
        markers = reference_markers(8, seed=2)
        boards = [
            FakeOakDevice("FAKE0001", rig.cameras[:2], markers, seed=1),
            FakeOakDevice("FAKE0002", rig.cameras[2:], markers, seed=2),
        ]
        driver = OakDriver("FAKE0001,FAKE0002", boards=boards, settings=CameraSettings(fps=300))
    try:
        yield driver
    finally:
        driver.close()


class TestOakConformance(OakConformance):
    """Every test of the OAK suite, against ``oak_driver``."""
