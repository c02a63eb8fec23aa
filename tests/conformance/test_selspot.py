"""SPX conformance: the simulator in CI, a real device with ``--hw selspot=PORT``.

The shared MCS-1 suite (:mod:`spotlab.testing.mcs1_conformance`) with the SPX
description, and the SPX-only tests (the LED table and the slot timing), in
:mod:`spotlab.testing.family_conformance` where ``spotlab bench`` runs them too.
"""

from __future__ import annotations

from spotlab.testing.family_conformance import SelspotConformance


class TestSelspotConformance(SelspotConformance):
    """Every test of the MCS-1 suite, and the SPX ones, against ``device_port``."""
