"""spotlab: acquisition suite for optoelectronic motion measurement."""

from spotlab.core import (
    ConfigurationError,
    DeviceError,
    Frame,
    FrameBlock,
    ProtocolError,
    RecordingError,
    SpotlabError,
    StreamSpec,
)

__version__ = "0.1.0"

__all__ = [
    "ConfigurationError",
    "DeviceError",
    "Frame",
    "FrameBlock",
    "ProtocolError",
    "RecordingError",
    "SpotlabError",
    "StreamSpec",
    "__version__",
]
