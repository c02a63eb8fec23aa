"""Qualisys QTM real-time servers as devices: labelled 3-D markers over TCP (or UDP).

The protocol is Qualisys' (docs/protocols/qualisys.md, version 1.25,
little-endian); :mod:`~spotlab.drivers.qualisys.protocol` reads its packets,
:class:`QualisysDecoder` turns QTM's bytes into frame blocks (live and in
replay), :class:`QualisysDriver` connects, negotiates and streams.
"""

from spotlab.drivers.qualisys.bodies import RigidBodies, bodies_from_recording
from spotlab.drivers.qualisys.decoder import QualisysDecoder, decoder_from_metadata
from spotlab.drivers.qualisys.driver import QualisysDriver, parse_address
from spotlab.drivers.qualisys.protocol import (
    PacketSplitter,
    QtmParameters,
    bodies_6d_from,
    command_packet,
    markers_2d_from,
    markers_3d_from,
    markers_no_labels_from,
    parse_data,
    parse_parameters,
)

__all__ = [
    "PacketSplitter",
    "QtmParameters",
    "QualisysDecoder",
    "QualisysDriver",
    "RigidBodies",
    "bodies_6d_from",
    "bodies_from_recording",
    "command_packet",
    "decoder_from_metadata",
    "markers_2d_from",
    "markers_3d_from",
    "markers_no_labels_from",
    "parse_address",
    "parse_data",
    "parse_parameters",
]
