"""Core: units, stream descriptions, frames, counters, checksums and errors."""

from spotlab.core.crc import crc16, crc16_hex, crc32
from spotlab.core.errors import (
    BandwidthError,
    CalibrationError,
    ClockError,
    ConfigurationError,
    DeviceDisconnected,
    DeviceError,
    DeviceNotFound,
    DeviceTimeout,
    ProtocolError,
    ReconstructionError,
    RecordingError,
    SpotlabError,
    SynchronisationError,
)
from spotlab.core.frames import Frame, FrameBlock
from spotlab.core.streams import STREAM_KINDS, StreamSpec
from spotlab.core.ticks import CounterUnwrapper, unwrap_counter
from spotlab.core.units import NS_PER_S, ns_to_seconds, seconds_to_ns

__all__ = [
    "NS_PER_S",
    "STREAM_KINDS",
    "BandwidthError",
    "CalibrationError",
    "ClockError",
    "ConfigurationError",
    "CounterUnwrapper",
    "DeviceDisconnected",
    "DeviceError",
    "DeviceNotFound",
    "DeviceTimeout",
    "Frame",
    "FrameBlock",
    "ProtocolError",
    "ReconstructionError",
    "RecordingError",
    "SpotlabError",
    "StreamSpec",
    "SynchronisationError",
    "crc16",
    "crc16_hex",
    "crc32",
    "ns_to_seconds",
    "seconds_to_ns",
    "unwrap_counter",
]
