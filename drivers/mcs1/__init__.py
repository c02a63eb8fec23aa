"""MCS-1, the serial transport shared by spotlab's device families (docs/protocols/mcs1.md).

* :mod:`~spotlab.drivers.mcs1.commands` — command encoding, reply parsing, error codes;
* :mod:`~spotlab.drivers.mcs1.framing` — stream frames cut out of the byte stream;
* :mod:`~spotlab.drivers.mcs1.sequence` — losses, duplicates and restarts from the counters;
* :mod:`~spotlab.drivers.mcs1.link` — the serial port (any pyserial URL) with arrival stamps;
* :mod:`~spotlab.drivers.mcs1.session` — reset, commands and baud negotiation.

A family adds its payload layout and its state machine on top (see ``drivers/selspot``).
"""

from spotlab.drivers.mcs1.commands import (
    BANNER,
    BAUD_CODES,
    DeviceBandwidthError,
    DeviceConfigurationError,
    Reply,
    encode_command,
    parse_reply,
)
from spotlab.drivers.mcs1.framing import EventFrame, FrameBatch, FrameDecoder
from spotlab.drivers.mcs1.link import SerialLink
from spotlab.drivers.mcs1.sequence import SequenceTracker
from spotlab.drivers.mcs1.session import CommandChannel

__all__ = [
    "BANNER",
    "BAUD_CODES",
    "CommandChannel",
    "DeviceBandwidthError",
    "DeviceConfigurationError",
    "EventFrame",
    "FrameBatch",
    "FrameDecoder",
    "Reply",
    "SequenceTracker",
    "SerialLink",
    "encode_command",
    "parse_reply",
]
