"""The MCS-1 verbs every family shares (mcs1.md §3), as the command half of the device base.

Each handler gets the parsed command and the world time its last byte
arrived, and returns the reply text, or None when it queued its reply itself
(``COMM:`` answers at the old rate, ``START:`` and ``STOP:`` change the stream
around their reply, ``RESET:`` answers with the banner). A refusal raises
:class:`CommandError` with the ERRORxx code. The order of the checks follows
the specs: ``0C`` (streaming) first, then ``07`` (parameter count), then the
values (``23``); ``START:`` then asks the family (:meth:`_check_start`).

A family supplies its configuration (:meth:`_default_config`), its ``VER:0``
text, its own verbs (:meth:`_family_handlers`), the ``START:`` checks and its
stream (:meth:`_new_stream`); :class:`~spotlab.simulators.mcs1_device.Mcs1Device`
provides the state the handlers act on.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping
from typing import ClassVar, Generic, Protocol, TypeVar

from spotlab.simulators import wire
from spotlab.simulators.clock import DeviceClock
from spotlab.simulators.commands import Command, CommandError
from spotlab.simulators.faults import FaultEntry, FaultInjector, FaultLog
from spotlab.simulators.line import Chunk, TxLine
from spotlab.simulators.mcs1_stream import Mcs1Stream

Handler = Callable[[Command, int], "str | None"]


class RateConfig(Protocol):
    """What the common verbs need of a family's configuration."""

    rate_mhz: int


ConfigT = TypeVar("ConfigT", bound=RateConfig)


class Mcs1Commands(ABC, Generic[ConfigT]):
    """Handlers of the common verbs and the checks every handler uses.

    Class attributes
    ----------------
    BAUD_RATES : mapping of int to int
        ``COMM:<c>`` code -> baud rate.
    RATE_RANGE_MHZ : (int, int)
        The frame rates ``RATE:`` accepts, in mHz.
    """

    BAUD_RATES: ClassVar[Mapping[int, int]] = wire.BAUD_RATES
    RATE_RANGE_MHZ: ClassVar[tuple[int, int]] = (1_000, 10_000_000)

    clock: DeviceClock
    faults: FaultInjector
    line: TxLine
    serial: str
    _config: ConfigT
    _stream: Mcs1Stream | None
    _streams: int
    _baud: int
    _baud_switch: tuple[int, int] | None
    _stat_latch: int
    _overflow_left: int
    _default_rate_mhz: int
    _power_on: Callable[[int, FaultEntry | None], None]
    _reply: Callable[[str, int], Chunk]
    _latch: Callable[[int], None]

    # ------------------------------------------------------- the family's part
    @abstractmethod
    def _default_config(self) -> ConfigT:
        """The configuration after reset or ``INIT:``."""

    @abstractmethod
    def version_text(self) -> str:
        """The ``VER:0`` reply text."""

    @abstractmethod
    def _family_handlers(self) -> dict[str, Handler]:
        """Verb -> handler of the family's own verbs (``CONF`` among them)."""

    @abstractmethod
    def _check_start(self) -> None:
        """Raise :class:`CommandError` when the configuration cannot stream (after 0C, 07)."""

    @abstractmethod
    def _new_stream(self, t: int, index: int) -> Mcs1Stream:
        """The stream ``START:`` at ``t`` begins, on a copy of the configuration."""

    def _status_now(self, t: int) -> int:
        """Status bits that hold at ``t`` whatever the latch (``STAT:``); none by default."""
        return 0

    def _stream_stopping(self, stream: Mcs1Stream) -> None:
        """``STOP:`` is ending ``stream`` (its reply queued); nothing by default."""

    # ------------------------------------------------------------------ table
    @property
    def fault_log(self) -> FaultLog:
        """The exact log of injected faults."""
        return self.faults.log

    def handlers(self) -> dict[str, Handler]:
        """Verb -> handler: the common verbs, then the family's (which may replace them)."""
        common: dict[str, Handler] = {
            "RESET": self._cmd_reset, "INIT": self._cmd_init, "VER": self._cmd_ver,
            "COMM": self._cmd_comm, "RATE": self._cmd_rate, "START": self._cmd_start,
            "STOP": self._cmd_stop, "STAT": self._cmd_stat, "TIME": self._cmd_time,
        }  # fmt: skip
        return {**common, **self._family_handlers()}

    # ----------------------------------------------------------------- checks
    def _not_streaming(self) -> None:
        if self._stream is not None:
            raise CommandError(0x0C)

    @staticmethod
    def _no_params(cmd: Command) -> None:
        if cmd.params:
            raise CommandError(0x07)

    @staticmethod
    def _int_param(cmd: Command, lo: int, hi: int, count: int = 1, index: int = 0) -> int:
        if len(cmd.params) != count:
            raise CommandError(0x07)
        text = cmd.params[index]
        if not (text.isascii() and text.isdigit()) or not lo <= int(text) <= hi:
            raise CommandError(0x23)
        return int(text)

    def _configured(self) -> str:
        self._latch(wire.STATUS_CONFIG_CHANGED)
        return "OKAY"

    # ------------------------------------------------------------ common verbs
    def _cmd_reset(self, cmd: Command, t: int) -> None:
        self._power_on(t, None)

    def _cmd_init(self, cmd: Command, t: int) -> str:
        self._not_streaming()
        self._no_params(cmd)
        self._config = self._default_config()
        return self._configured()

    def _cmd_ver(self, cmd: Command, t: int) -> str:
        self._int_param(cmd, 0, 0)
        return self.version_text()

    def _cmd_comm(self, cmd: Command, t: int) -> None:
        self._not_streaming()
        code = self._int_param(cmd, 0, max(self.BAUD_RATES))
        chunk = self._reply("OKAY", t)
        self._baud_switch = (chunk.end_ns, self.BAUD_RATES[code])

    def _cmd_rate(self, cmd: Command, t: int) -> str:
        self._not_streaming()
        self._config.rate_mhz = self._int_param(cmd, *self.RATE_RANGE_MHZ)
        return self._configured()

    def _cmd_stat(self, cmd: Command, t: int) -> str:
        self._no_params(cmd)
        status = self._stat_latch | self._status_now(t)
        self._stat_latch = 0
        return f"STAT {status:04X}"

    def _cmd_time(self, cmd: Command, t: int) -> str:
        self._no_params(cmd)
        rx = self.clock.ticks(t) & 0xFFFFFFFF
        tx = self.clock.ticks(self.line.start_time(t)) & 0xFFFFFFFF
        return f"TIME {rx:08X} {tx:08X}"

    def _cmd_start(self, cmd: Command, t: int) -> None:
        self._not_streaming()
        self._no_params(cmd)
        self._check_start()
        self._anchor_faults(t)
        self._reply("OKAY", t)
        self._stream = self._new_stream(t, self._streams)
        self._streams += 1
        self._overflow_left = 0

    def _anchor_faults(self, t: int) -> None:
        """At the first ``START:``: fix the fault schedule's zero and plan the disconnects."""
        if self.faults.anchor(t):
            for spec in self.faults.timed_specs:
                if spec.kind == "disconnect" and spec.arg is not None:
                    t0 = self.faults.at_ns(spec)
                    entry = self.fault_log.new("disconnect", spec.at_s, t0, "schedule", spec.arg)
                    self.line.add_down(t0, t0 + round(spec.arg * 1e9), entry.id)

    def _cmd_stop(self, cmd: Command, t: int) -> str | None:
        self._no_params(cmd)
        if self._stream is None:
            return "OKAY"
        self._reply("OKAY", t)
        self._stream_stopping(self._stream)
        self._stream = None
        return None
