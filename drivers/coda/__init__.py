"""Optomechanical scanners: CSX protocol over MCS-1 (docs/protocols/coda.md)."""

from spotlab.drivers.coda.config import CodaConfig, marker_code, marker_id
from spotlab.drivers.coda.driver import CodaDriver
from spotlab.drivers.coda.protocol import CodaDecoder, CodaVersion, decoder_from_metadata

__all__ = [
    "CodaConfig",
    "CodaDecoder",
    "CodaDriver",
    "CodaVersion",
    "decoder_from_metadata",
    "marker_code",
    "marker_id",
]
