"""What a session needs of a device and of a sink (python-can's bus and listener).

A device is anything that behaves like ``spotlab.drivers.base.Driver``; the
acquisition layer never imports drivers or simulators, so tests and third-party
code may pass their own objects.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Sequence
from typing import Any, Protocol, runtime_checkable

from spotlab.core.frames import FrameBlock
from spotlab.core.stats import LinkStats
from spotlab.core.streams import StreamSpec
from spotlab.core.wire import WireTap


@runtime_checkable
class Device(Protocol):
    """A source of frame blocks: a driver, a simulator link, a test fake.

    Attributes
    ----------
    name : str
        Stream name, unique within a session.
    stats : LinkStats
        Counters of the link, updated by ``recv``.
    """

    name: str
    stats: LinkStats

    @property
    def spec(self) -> StreamSpec:
        """Description of the stream (valid after :meth:`start`)."""
        ...

    def start(self) -> None:
        """Open the link, configure the device, start streaming."""

    def stop(self) -> None:
        """Stop streaming; the link stays open."""

    def close(self) -> None:
        """Stop and release the port; safe to call twice."""

    def recv(self, timeout: float | None = None) -> FrameBlock | None:
        """Frames decoded since the last call, or None after ``timeout`` seconds."""

    def add_tap(self, tap: WireTap) -> None:
        """Register a listener of every byte and link event."""

    def metadata(self) -> dict[str, Any]:
        """JSON-safe facts needed to decode the stream again (``family``, ``spec``...)."""


@runtime_checkable
class Sink(Protocol):
    """A consumer of frame blocks, fed by its own dispatcher thread.

    A sink may also define ``on_start(devices)``, called once the devices are
    started and before any block arrives, and may be a :class:`WireTap`
    (``on_rx``, ``on_tx``, ``on_event``): the session then registers it on
    every device before starting them.
    """

    def on_block(self, stream: str, block: FrameBlock) -> None:
        """New frames of ``stream``. The block is shared between sinks: do not modify it."""

    def on_error(self, stream: str, exc: BaseException) -> None:
        """The device of ``stream`` raised ``exc`` in ``recv``."""

    def stop(self) -> None:
        """The session ended: every block has been delivered. Release resources."""


@runtime_checkable
class InlineSink(Sink, Protocol):
    """A sink the session calls from the device's reader thread, with no hand-off.

    ``inline`` must be ``True``. ``on_block`` and ``on_error`` then run in every
    reader thread right after ``recv`` returned: they must be quick (they delay the
    next read) and thread-safe (several devices' readers may call them at once).
    Their exceptions are counted as sink errors and never end the reader.
    """

    inline: bool


class SinkBase(ABC):
    """Convenience base for sinks: override :meth:`on_block`, the rest are no-ops.

    Attributes
    ----------
    name : str
        Name under which the session reports this sink's overflows.
    """

    name: str = ""

    def on_start(self, devices: Sequence[Device]) -> None:  # noqa: B027 - optional hook
        """The devices are started; no block has been delivered yet."""

    @abstractmethod
    def on_block(self, stream: str, block: FrameBlock) -> None:
        """New frames of ``stream``. The block is shared between sinks: do not modify it."""

    def on_error(self, stream: str, exc: BaseException) -> None:  # noqa: B027 - optional hook
        """The device of ``stream`` raised ``exc`` in ``recv``."""

    def stop(self) -> None:  # noqa: B027 - optional hook
        """The session ended: every block has been delivered."""
