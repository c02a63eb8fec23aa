"""The conformance suite of every MCS-1 family with the family's own tests.

:class:`SelspotConformance`, :class:`TimerConformance`, :class:`CentroidConformance`
and :class:`CodaConformance` are the shared suite
(:class:`~spotlab.testing.mcs1_conformance.Mcs1Conformance`) with the family's
description and the tests only that family needs. ``tests/conformance`` runs them
against the simulators (and a device with ``--hw``); ``spotlab bench`` runs them
against the port it is given.
"""

from __future__ import annotations

import pytest
import serial

from spotlab.core.errors import ConfigurationError
from spotlab.drivers.coda import CodaDriver
from spotlab.testing.mcs1_conformance import Mcs1Conformance
from spotlab.testing.mcs1_families import CENTROID, CODA, SELSPOT, TIMER
from spotlab.testing.wire import ask

ERROR_OUT_OF_RANGE = "ERROR23"
ERROR_BAD_LED_TABLE = "ERROR81"
ERROR_NOT_CONFIGURED = "ERROR82"


class SelspotConformance(Mcs1Conformance):
    """Every test of the MCS-1 suite, and the SPX ones: the LED table and the slot timing."""

    family = SELSPOT

    def test_bad_led_tables_are_error_81(self, link: serial.Serial) -> None:
        assert ask(link, "LEDT:0080") == "OKAY"
        assert ask(link, "LEDT:00800080") == ERROR_BAD_LED_TABLE  # id twice
        assert ask(link, "LEDT:8080") == ERROR_BAD_LED_TABLE  # id above 7F
        assert ask(link, "LEDT:008") == ERROR_BAD_LED_TABLE  # not a multiple of 4

    def test_led_table_reads_back(self, link: serial.Serial) -> None:
        assert ask(link, "LEDT:008005C01140") == "OKAY"
        assert ask(link, "LEDQ:") == "LEDQ 008005C01140"

    def test_start_without_led_table_is_error_82(self, link: serial.Serial) -> None:
        assert ask(link, "START:") == ERROR_NOT_CONFIGURED

    def test_timing_is_checked_at_start(self, link: serial.Serial) -> None:
        # 128 LEDs of 100 us slots take 12.9 ms: 100 Hz frames cannot hold them.
        table = "".join(f"{i:02X}80" for i in range(128))
        assert ask(link, f"LEDT:{table}") == "OKAY"
        assert ask(link, "RATE:100000") == "OKAY"
        assert ask(link, "START:") == ERROR_OUT_OF_RANGE


class TimerConformance(Mcs1Conformance):
    """Every test of the MCS-1 suite, and the TMR one: the counter a pulse reply carries."""

    family = TIMER

    def test_pulse_reply_carries_a_counter_on_a_whole_microsecond(
        self, link: serial.Serial
    ) -> None:
        a = int(ask(link, "PULS:0").split()[1], 16)
        b = int(ask(link, "PULS:0").split()[1], 16)
        assert a % 10 == 0 and b % 10 == 0
        assert 0 < b - a < 20_000_000  # less than 2 s between the two


class CentroidConformance(Mcs1Conformance):
    """Every test of the MCS-1 suite (the CEN checks of exposure and blob tables are in
    the description)."""

    family = CENTROID


class CodaConformance(Mcs1Conformance):
    """Every test of the MCS-1 suite, and the CSX ones: the ``CONF`` reply names the marker
    table by colour codes, and a unit of another geometry than the one asked for is
    refused."""

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


__all__ = ["CentroidConformance", "CodaConformance", "SelspotConformance", "TimerConformance"]
