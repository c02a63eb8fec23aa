"""TMR conformance: the simulator in CI, a real unit with ``--hw timer=PORT``.

The shared MCS-1 suite (:mod:`spotlab.testing.mcs1_conformance`) with the TMR
description, and the TMR-only test (the counter a pulse reply carries), in
:mod:`spotlab.testing.family_conformance` where ``spotlab bench`` runs it too.
"""

from __future__ import annotations

from spotlab.testing.family_conformance import TimerConformance


class TestTimerConformance(TimerConformance):
    """Every test of the MCS-1 suite, and the TMR one, against ``device_port``."""
