"""CSX conformance: the simulator in CI, a real unit with ``--hw coda=PORT``.

The shared MCS-1 suite (:mod:`spotlab.testing.mcs1_conformance`) with the CSX
description, and the CSX-only tests: the ``CONF`` reply names the marker table by
colour codes, and the ``VER:0`` geometry is the one the driver refuses to mix up.
"""

from __future__ import annotations

import pytest
import serial

from spotlab.core.errors import ConfigurationError
from spotlab.drivers.coda import CodaDriver
from spotlab.testing.mcs1_conformance import Mcs1Conformance
from spotlab.testing.mcs1_families import CODA
from spotlab.testing.wire import ask


class TestCodaConformance(Mcs1Conformance):
    """Every test of the MCS-1 suite, and the CSX ones, against ``device_port``."""

    family = CODA

    def test_conf_names_the_marker_table_by_colour_codes(self, link: serial.Serial) -> None:
        assert ask(link, "MARK:RO,GB") == "OKAY"
        assert ask(link, "OUT:RAW") == "OKAY"
        words = ask(link, "CONF:").split()
        assert words[0] == "CONF" and "OUT=RAW" in words and "MARK=RO,GB" in words

    def test_a_unit_of_another_geometry_is_refused_in_one_line(self, device_port: str) -> None:
        driver = CodaDriver(device_port, markers=2, base_mm=1234.0)
        with pytest.raises(ConfigurationError, match=r"mirror base of .* not the 1234 mm"):
            driver.start()
        driver.close()
