"""QTM conformance: the simulator in CI, a real QTM with ``--hw qualisys=HOST[:PORT]``.

The suite is :mod:`spotlab.testing.qualisys_conformance` (``SPOTLAB_QTM_PASSWORD``
for the control tests on a real QTM, ``SPOTLAB_QTM_SECONDS`` for how long to stream).
"""

from __future__ import annotations

from spotlab.testing.qualisys_conformance import QualisysConformance


class TestQualisysConformance(QualisysConformance):
    """Every test of the QTM suite against ``qtm_address``."""
