"""LSL (Lab Streaming Layer) outlets: spotlab streams for other hosts and lab software.

Needs the ``lsl`` extra (``pip install 'spotlab[lsl]'``); nothing here opens a
network port until an outlet is created. See docs/lsl.md.
"""

from spotlab.acquisition.lsl._pylsl import configure
from spotlab.acquisition.lsl.clock import LslClock
from spotlab.acquisition.lsl.metadata import (
    MOCAP_TYPE,
    RAW_TYPE,
    marker_labels,
    spec_from_info,
    stream_info,
)
from spotlab.acquisition.lsl.outlet import LslOutlet, MarkerOutlet, marker_spec
from spotlab.acquisition.lsl.sink import LslOutletSink, TimeOf

__all__ = [
    "MOCAP_TYPE",
    "RAW_TYPE",
    "LslClock",
    "LslOutlet",
    "LslOutletSink",
    "MarkerOutlet",
    "TimeOf",
    "configure",
    "marker_labels",
    "marker_spec",
    "spec_from_info",
    "stream_info",
]
