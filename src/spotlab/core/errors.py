"""Errors that name their cause.

Every error spotlab raises derives from :class:`SpotlabError`, so a caller (the
command line among them) can tell a user mistake or a device fault from a bug.
The message always says what went wrong and, where it can, what to do about it.
"""

from __future__ import annotations


class SpotlabError(Exception):
    """Base class of every error spotlab raises on purpose."""


class ConfigurationError(SpotlabError, ValueError):
    """A requested configuration is invalid or cannot be carried out."""


class BandwidthError(ConfigurationError):
    """A configuration needs more bytes per second than the line can carry."""


class ProtocolError(SpotlabError):
    """Bytes on the wire do not follow the documented protocol."""


class DeviceError(SpotlabError):
    """The device refused a command or is not in a usable state.

    Parameters
    ----------
    message : str
        What went wrong.
    code : int, optional
        The device's own error code (``ERRORxx``), when it sent one.
    """

    def __init__(self, message: str, code: int | None = None) -> None:
        super().__init__(message)
        self.code = code


class DeviceTimeout(DeviceError, TimeoutError):
    """The device did not answer within the allowed time."""


class DeviceNotFound(DeviceError):
    """No device answers at the given port or URL."""


class DeviceDisconnected(DeviceError):
    """The port went away while in use (cable pulled, device power-cycled)."""


class RecordingError(SpotlabError):
    """A recording (journal) cannot be read, or can be read only in part."""


class CalibrationError(SpotlabError, ValueError):
    """Calibration input is degenerate or the solution did not converge."""


class ReconstructionError(SpotlabError, ValueError):
    """Reconstruction input is degenerate (too few views, collinear markers, ...)."""


class ClockError(SpotlabError, ValueError):
    """Clock-model input is unusable (too few pairs, NaN, ticks going backwards, a stopped
    reference) or a clock model cannot be fitted or applied."""


class SynchronisationError(SpotlabError, ValueError):
    """Streams cannot be put on one time base (times not increasing, seq going back, ...)."""
