"""The driver base class, in the style of python-can's ``BusABC``.

A family implements ``_recv_internal`` (and its set-up in ``_start``); the
public :meth:`Driver.recv` adds the timeout handling, statistics and listener
calls once for all families.
"""

from __future__ import annotations

import os
import time
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from types import TracebackType
from typing import Any, ClassVar

from spotlab.core.frames import FrameBlock
from spotlab.core.stats import LinkStats
from spotlab.core.streams import StreamSpec
from spotlab.core.wire import LinkEventKind, WireTap


@dataclass(frozen=True)
class DeviceInfo:
    """A device found by :meth:`Driver.detect`.

    Attributes
    ----------
    family : str
        Driver family name (``"selspot"``).
    port : str
        Path or pyserial URL to open it with.
    description : str
        What the device said of itself (version reply), or what the OS says.
    serial_number : str
        Serial number, empty when unknown.
    extra : dict
        Family-specific facts (cameras, LEDs, firmware).
    """

    family: str
    port: str
    description: str = ""
    serial_number: str = ""
    extra: dict[str, Any] = field(default_factory=dict)


class Driver(ABC):
    """A device link that delivers :class:`FrameBlock` objects.

    Subclasses set ``family`` and implement :meth:`_start`, :meth:`_stop`,
    :meth:`_close` and :meth:`_recv_internal`.

    Parameters
    ----------
    port : str or path-like
        Device path (``/dev/ttyUSB0``) or pyserial URL (``socket://``, ``sim://``...).
    name : str, optional
        Stream name; defaults to the family name.
    """

    family: ClassVar[str] = ""

    def __init__(self, port: str | os.PathLike[str], *, name: str | None = None) -> None:
        self.port: str = os.fspath(port)
        self.name = name or self.family
        self.stats = LinkStats()
        self._taps: list[WireTap] = []
        self._started = False

    # -- listeners ---------------------------------------------------------
    def add_tap(self, tap: WireTap) -> None:
        """Register a listener of every byte and link event of this driver."""
        self._taps.append(tap)

    def _tap_rx(self, data: bytes, t_ns: int) -> None:
        for tap in self._taps:
            tap.on_rx(self.name, data, t_ns)

    def _tap_tx(self, data: bytes, t_ns: int) -> None:
        for tap in self._taps:
            tap.on_tx(self.name, data, t_ns)

    def _tap_event(self, kind: LinkEventKind, **detail: object) -> None:
        t_ns = time.monotonic_ns()
        for tap in self._taps:
            tap.on_event(self.name, kind, dict(detail), t_ns)

    # -- life cycle --------------------------------------------------------
    @property
    @abstractmethod
    def spec(self) -> StreamSpec:
        """Description of the stream this driver delivers (valid after start)."""

    def metadata(self) -> dict[str, Any]:
        """JSON-safe facts a recording needs to decode this stream again."""
        return {"family": self.family, "port": self.port, "spec": self.spec.to_dict()}

    def start(self) -> None:
        """Open the link, bring the device to a known state, configure it, stream."""
        if self._started:
            return
        self._start()
        self._started = True

    def stop(self) -> None:
        """Stop streaming; the link stays open."""
        if self._started:
            self._started = False
            self._stop()

    def close(self) -> None:
        """Stop streaming and release the port. Safe to call twice."""
        try:
            self.stop()
        finally:
            self._close()

    def recv(self, timeout: float | None = None) -> FrameBlock | None:
        """Frames decoded since the last call.

        Parameters
        ----------
        timeout : float, optional
            Seconds to wait for at least one frame; ``None`` waits forever.

        Returns
        -------
        FrameBlock or None
            The frames, or ``None`` when none arrived before the timeout.
        """
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            remaining = None if deadline is None else max(0.0, deadline - time.monotonic())
            block = self._recv_internal(remaining)
            if block is not None and len(block):
                return block
            if deadline is not None and time.monotonic() >= deadline:
                return None

    @abstractmethod
    def _start(self) -> None: ...

    @abstractmethod
    def _stop(self) -> None: ...

    @abstractmethod
    def _close(self) -> None: ...

    @abstractmethod
    def _recv_internal(self, timeout: float | None) -> FrameBlock | None:
        """Read what the link has, decode it; return a (possibly empty) block or None."""

    @classmethod
    def detect(cls) -> list[DeviceInfo]:
        """Devices of this family that answer on this machine's ports."""
        return []

    def __enter__(self) -> Driver:
        self.start()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()
