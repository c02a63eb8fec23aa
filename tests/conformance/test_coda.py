"""CSX conformance: the simulator in CI, a real unit with ``--hw coda=PORT``.

The shared MCS-1 suite (:mod:`spotlab.testing.mcs1_conformance`) with the CSX
description, and the CSX-only tests, in :mod:`spotlab.testing.family_conformance`
where ``spotlab bench`` runs them too.
"""

from __future__ import annotations

from spotlab.testing.family_conformance import CodaConformance


class TestCodaConformance(CodaConformance):
    """Every test of the MCS-1 suite, and the CSX ones, against ``device_port``."""
