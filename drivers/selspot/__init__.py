"""Lateral-photodiode (SELSPOT-style) camera systems: SPX protocol over MCS-1."""

from spotlab.drivers.selspot.config import SelspotConfig
from spotlab.drivers.selspot.driver import SelspotDriver
from spotlab.drivers.selspot.protocol import SelspotDecoder, decoder_from_metadata

__all__ = ["SelspotConfig", "SelspotDecoder", "SelspotDriver", "decoder_from_metadata"]
