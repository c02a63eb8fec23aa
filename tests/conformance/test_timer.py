"""TMR conformance: the simulator in CI, a real unit with ``--hw timer=PORT``.

The shared MCS-1 suite (:mod:`spotlab.testing.mcs1_conformance`) with the TMR
description, and the TMR-only test: the counter a pulse reply carries.
"""

from __future__ import annotations

import serial

from spotlab.testing.mcs1_conformance import Mcs1Conformance
from spotlab.testing.mcs1_families import TIMER
from spotlab.testing.wire import ask


class TestTimerConformance(Mcs1Conformance):
    """Every test of the MCS-1 suite, and the TMR one, against ``device_port``."""

    family = TIMER

    def test_pulse_reply_carries_a_counter_on_a_whole_microsecond(
        self, link: serial.Serial
    ) -> None:
        a = int(ask(link, "PULS:0").split()[1], 16)
        b = int(ask(link, "PULS:0").split()[1], 16)
        assert a % 10 == 0 and b % 10 == 0
        assert 0 < b - a < 20_000_000  # less than 2 s between the two
