"""LSL inlets as devices: a stream from another program or host joins a session."""

from spotlab.drivers.lsl.driver import PROPERTIES, LslInletDriver, parse_port
from spotlab.drivers.lsl.wire import LslChunkDecoder, decoder_from_metadata, encode_chunk

__all__ = [
    "PROPERTIES",
    "LslChunkDecoder",
    "LslInletDriver",
    "decoder_from_metadata",
    "encode_chunk",
    "parse_port",
]
