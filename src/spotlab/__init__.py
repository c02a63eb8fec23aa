"""spotlab: acquisition suite for optoelectronic motion measurement."""

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
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
    from spotlab.geometry import Camera, Rig

__version__ = "0.1.0"

# Loaded on first use so that `import spotlab` stays light (no numpy, no scipy):
# `spotlab --version` and a Ctrl-C at start-up need nothing more.
_LAZY = {
    "Camera": "spotlab.geometry",
    "Rig": "spotlab.geometry",
    **dict.fromkeys(
        (
            "ConfigurationError",
            "DeviceError",
            "Frame",
            "FrameBlock",
            "ProtocolError",
            "RecordingError",
            "SpotlabError",
            "StreamSpec",
        ),
        "spotlab.core",
    ),
}


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'spotlab' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


__all__ = [
    "Camera",
    "ConfigurationError",
    "DeviceError",
    "Frame",
    "FrameBlock",
    "ProtocolError",
    "RecordingError",
    "Rig",
    "SpotlabError",
    "StreamSpec",
    "__version__",
]
