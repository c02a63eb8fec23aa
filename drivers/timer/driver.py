"""The TMR timer/sync unit driver (timer.md §7): the MCS-1 state machine with the timer's set-up.

:class:`TimerDriver` resets, negotiates, checks ``VER:0`` (``TMR``, enough
inputs, 10 MHz counter), sends ``RATE``, ``EDGS``, ``TCOD`` and one ``ARM`` per
input, and starts the stream; recovery is :class:`Mcs1Driver`'s. :meth:`pulse`
fires an output while streaming and returns the counter at the pulse.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from typing import Any, ClassVar

from spotlab.core.errors import ConfigurationError, ProtocolError
from spotlab.core.streams import StreamSpec
from spotlab.drivers.mcs1.commands import Reply
from spotlab.drivers.mcs1.family import FamilyDriver
from spotlab.drivers.timer.config import MAX_INPUTS, TimerConfig
from spotlab.drivers.timer.protocol import (
    FAMILY_CODE,
    TICK_HZ,
    UNITS,
    VALUES,
    TimerDecoder,
    TimerVersion,
)


class TimerDriver(FamilyDriver[TimerConfig, TimerDecoder, TimerVersion]):
    """Driver of a TMR timer/sync unit.

    Parameters
    ----------
    port : str or path-like
        Device path or pyserial URL (``sim://timer?...``).
    name : str, optional
        Stream name; ``"timer"`` by default.
    rate_hz : float, optional
        Timer frame rate in Hz.
    slots : int, optional
        Edge record slots per frame.
    inputs : mapping of int to str, optional
        Input -> ``"rising"``, ``"falling"``, ``"both"`` or ``"off"``; default
        every input armed for rising edges (frame pulses rise at frame start).
    timecode : (int, bool), optional
        ``(fps, drop_frame)`` to have LTC labels in every frame.

    ``rate_hz``, ``slots`` and ``timecode`` not given (None) keep what the unit reports it
    has (``CONF:``, read once at :meth:`start`); a unit that does not know ``CONF:`` gets
    100 Hz, 8 slots and no timecode.
    baud : int or "auto"
        Line rate while streaming.
    reply_timeout, reconnect_timeout : float
        As :class:`~spotlab.drivers.mcs1.driver.Mcs1Driver`.

    Raises
    ------
    ConfigurationError
        If the configuration is out of range.
    BandwidthError
        If the stream does not fit ``baud``.
    """

    family = "timer"
    family_code = FAMILY_CODE
    decoder_path = "spotlab.drivers.timer:decoder_from_metadata"
    config_class = TimerConfig
    decoder_class = TimerDecoder
    version_class = TimerVersion
    device_keys = ("rate_hz", "slots", "timecode")
    conf_verbs: ClassVar[Mapping[str, str]] = {"RATE": "rate_hz", "EDGS": "slots"}
    stream_kind = "timer"
    stream_tick_hz = float(TICK_HZ)
    values = VALUES
    units = UNITS
    info_fields = ("firmware", "inputs")

    def __init__(
        self,
        port: str | os.PathLike[str],
        *,
        name: str | None = None,
        rate_hz: float | None = None,
        slots: int | None = None,
        inputs: Mapping[int, str] | None = None,
        timecode: tuple[int, bool] | None = None,
        baud: int | str = 2_000_000,
        reply_timeout: float = 1.0,
        reconnect_timeout: float | None = None,
    ) -> None:
        given = {"rate_hz": rate_hz, "slots": slots, "timecode": timecode}
        fixed = {"inputs": inputs, "baud": baud}
        super().__init__(port, name, given, fixed, reply_timeout, reconnect_timeout)

    @property
    def spec(self) -> StreamSpec:
        """The stream: ``timer``, ``E + 1`` rows (edge slots, then timecode), 10 MHz ticks."""
        return self._spec(1, self.config.slots + 1, layout="timer-edges-v1")

    def pulse(self, output: int) -> int:
        """Fire one pulse on ``output`` (0-3); returns the counter at the pulse (10 MHz ticks).

        Raises
        ------
        ProtocolError
            If the reply does not carry the pulse's tick.
        """
        reply = self.command(f"PULS:{int(output)}")
        fields = reply.text.split()
        if len(fields) != 2 or fields[0] != "PULS":
            raise ProtocolError(f"reply {reply.text!r} to PULS is not 'PULS <16 hex digits>'")
        value = int(fields[1], 16)
        return value - (1 << 64) if value >= 1 << 63 else value

    # -- family hooks ----------------------------------------------------------------
    def _conf_extras(self, fields: Mapping[str, str], out: dict[str, Any]) -> None:
        tc = [int(v) for v in fields.get("TCOD", "0").split(",")]
        if tc[0] == 1 and len(tc) == 3:
            out["timecode"] = (tc[1], bool(tc[2]))

    def _check_version(self, device: TimerVersion, reply: Reply) -> None:
        if device.inputs < MAX_INPUTS or device.tick_hz != TICK_HZ:
            raise ConfigurationError(
                f"the unit on {self.port} ({reply.text}) has {device.inputs} inputs and a "
                f"{device.tick_hz} Hz counter; this driver needs {MAX_INPUTS} inputs and "
                f"{TICK_HZ} Hz"
            )

    def _describe_load(self) -> str:
        c = self.config
        return f"timer frames of {c.slots} edge slots at {c.rate_hz:g} Hz"
