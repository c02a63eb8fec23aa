"""Timer/sync units: TMR protocol over MCS-1 (docs/protocols/timer.md)."""

from spotlab.drivers.timer.config import TimerConfig
from spotlab.drivers.timer.driver import TimerDriver
from spotlab.drivers.timer.edges import TimerEdges, edges_from_recording, extract_edges
from spotlab.drivers.timer.protocol import TimerDecoder, decoder_from_metadata

__all__ = [
    "TimerConfig",
    "TimerDecoder",
    "TimerDriver",
    "TimerEdges",
    "decoder_from_metadata",
    "edges_from_recording",
    "extract_edges",
]
