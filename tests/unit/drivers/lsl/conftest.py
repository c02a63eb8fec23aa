"""LSL tests resolve streams on this machine by unicast too (multicast may be blocked in CI).

liblsl reads its configuration at the first LSL call of the process, so it is set here,
at collection, before any test runs.
"""

from __future__ import annotations

from spotlab.acquisition.lsl import configure
from spotlab.core.errors import ConfigurationError

try:
    configure(("127.0.0.1",), log_level=-3)
except ConfigurationError:
    pass  # no pylsl: the tests skip themselves
