"""CEN conformance: the simulator in CI, a real hub with ``--hw centroid=PORT``.

The shared MCS-1 suite (:mod:`spotlab.testing.mcs1_conformance`) with the CEN
description (the hub should see at least one marker); the CEN checks of
exposure and blob tables are in the description.
"""

from __future__ import annotations

from spotlab.testing.family_conformance import CentroidConformance


class TestCentroidConformance(CentroidConformance):
    """Every test of the MCS-1 suite against ``device_port``."""
