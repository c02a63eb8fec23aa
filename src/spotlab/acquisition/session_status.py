"""What a session reports: its status, the errors its devices raised, which are fatal."""

from __future__ import annotations

from dataclasses import dataclass

from spotlab.core.errors import DeviceDisconnected, DeviceTimeout, ProtocolError

__all__ = ["DeviceErrorRecord", "SessionStatus", "default_is_fatal"]

_TRANSIENT = (ProtocolError, DeviceTimeout, DeviceDisconnected)


def default_is_fatal(exc: BaseException) -> bool:
    """Whether a device error ends its reader thread.

    Protocol errors, timeouts and disconnections are transient (the driver
    resynchronises or reconnects, the reader keeps calling ``recv``);
    anything else — a device refusing to work, a bug — is fatal.
    """
    return not isinstance(exc, _TRANSIENT)


@dataclass(frozen=True)
class DeviceErrorRecord:
    """An error a device raised in ``recv``.

    Attributes
    ----------
    stream : str
        The device's name.
    error : BaseException
        What it raised.
    t_ns : int
        Host monotonic time when it was caught.
    fatal : bool
        Whether it ended the device's reader thread.
    """

    stream: str
    error: BaseException
    t_ns: int
    fatal: bool


@dataclass(frozen=True)
class SessionStatus:
    """A snapshot for progress displays.

    Attributes
    ----------
    elapsed_s : float
        Seconds since the session started.
    target_s : float or None
        Planned duration (``run_for``), None when open-ended.
    frames : dict of str to int
        Frames received per stream.
    overflows : dict of str to int
        Blocks dropped per sink because its queue was full.
    errors : int
        Device errors so far.
    readers_alive : int
        Reader threads still running (a fatal error ends one).
    """

    elapsed_s: float
    target_s: float | None
    frames: dict[str, int]
    overflows: dict[str, int]
    errors: int
    readers_alive: int
