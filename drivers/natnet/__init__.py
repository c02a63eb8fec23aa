"""OptiTrack Motive's NatNet stream as a spotlab device (docs/protocols/natnet.md).

NatNet is OptiTrack's protocol; this family is a client of it, written from the
public sources the spec cites.
"""

from spotlab.drivers.natnet.decoding import LAYOUT, NatNetDecoder, decoder_from_metadata
from spotlab.drivers.natnet.driver import NatNetDriver, parse_address
from spotlab.drivers.natnet.wire import (
    FrameOfData,
    ModelDefinitions,
    NatNetFormatError,
    ServerInfo,
    parse_frame,
    parse_model_definitions,
    parse_server_info,
    split_packet,
)

__all__ = [
    "LAYOUT",
    "FrameOfData",
    "ModelDefinitions",
    "NatNetDecoder",
    "NatNetDriver",
    "NatNetFormatError",
    "ServerInfo",
    "decoder_from_metadata",
    "parse_address",
    "parse_frame",
    "parse_model_definitions",
    "parse_server_info",
    "split_packet",
]
