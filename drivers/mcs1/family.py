"""What an MCS-1 family driver is made of, once for every family: the MCS-1 kit.

:class:`FamilyDriver` is :class:`~spotlab.drivers.mcs1.driver.Mcs1Driver` (the
state machine: connect, negotiate, configure, stream, recover) with the family
hooks written once from a few class attributes:

* ``config_class`` — the family's configuration (``create(**keywords)``), built from
  the settings the user gave, over what the device reports it has (``CONF:``);
* ``decoder_class`` — its stream decoder (``from_config(config, stats=...)``);
* ``version_class`` — its ``VER:0`` reply, a
  :class:`~spotlab.drivers.mcs1.version.VersionReply`;
* ``device_keys`` — the ``create`` keywords the device keeps when not given;
* ``conf_verbs`` — ``CONF`` verb -> ``create`` keyword of its integer settings
  (``RATE`` is in mHz and becomes ``rate_hz``);
* ``info_fields`` — the ``VER:0`` fields :meth:`detect` reports in ``DeviceInfo.extra``.

The family keeps what is its own: its ``__init__`` keywords, ``spec`` (through
:meth:`FamilyDriver._spec`, with ``stream_kind``, ``stream_tick_hz``, ``values``
and ``units``), the
checks of :meth:`FamilyDriver._check_version`, :meth:`Mcs1Driver._describe_load`,
the ``CONF`` fields that are not one integer (:meth:`FamilyDriver._conf_extras`)
and its commands (``TimerDriver.pulse``).
"""

from __future__ import annotations

import os
from abc import abstractmethod
from collections.abc import Iterable, Mapping
from typing import Any, ClassVar, Generic, TypeVar

from spotlab.core.errors import ProtocolError
from spotlab.core.streams import StreamKind, StreamSpec
from spotlab.drivers.base import DeviceInfo
from spotlab.drivers.mcs1 import discovery
from spotlab.drivers.mcs1.commands import Reply
from spotlab.drivers.mcs1.contracts import Mcs1Config, Mcs1Decoder
from spotlab.drivers.mcs1.driver import Mcs1Driver
from spotlab.drivers.mcs1.version import VersionReply

ConfigT = TypeVar("ConfigT", bound=Mcs1Config)
DecoderT = TypeVar("DecoderT", bound=Mcs1Decoder)
VersionT = TypeVar("VersionT", bound=VersionReply)


class FamilyDriver(Mcs1Driver, Generic[ConfigT, DecoderT, VersionT]):
    """An MCS-1 family driver; the subclass sets the class attributes and its own hooks.

    Parameters
    ----------
    port : str or path-like
        Device path or pyserial URL.
    name : str or None
        Stream name; the family name when None.
    given : mapping of str to object
        The settings the device keeps when not given (``device_keys``), None where
        the user did not give one.
    fixed : mapping of str to object
        The other ``create`` keywords (always the user's).
    reply_timeout, reconnect_timeout : float
        As :class:`~spotlab.drivers.mcs1.driver.Mcs1Driver`.
    """

    #: The family's configuration class (``create(**keywords)``).
    config_class: ClassVar[type[Any]]
    #: The family's decoder class (``from_config(config, stats=...)``).
    decoder_class: ClassVar[type[Any]]
    #: The family's ``VER:0`` reply (a :class:`VersionReply`).
    version_class: ClassVar[type[Any]]
    #: ``create`` keywords the device keeps when they are not given.
    device_keys: ClassVar[tuple[str, ...]] = ()
    #: ``CONF`` verb -> ``create`` keyword, for the settings that are one integer.
    conf_verbs: ClassVar[Mapping[str, str]] = {}
    #: ``VER:0`` fields reported in ``DeviceInfo.extra``, in this order.
    info_fields: ClassVar[tuple[str, ...]] = ("firmware",)
    #: The stream's kind, tick rate (Hz), value names and units (:class:`StreamSpec`).
    stream_kind: ClassVar[StreamKind]
    stream_tick_hz: ClassVar[float]
    values: ClassVar[tuple[str, ...]]
    units: ClassVar[tuple[str, ...]]

    config: ConfigT
    _decoder: DecoderT
    #: What the device said of itself (``VER:0``), once started.
    device: VersionT | None

    def __init__(
        self,
        port: str | os.PathLike[str],
        name: str | None,
        given: Mapping[str, Any],
        fixed: Mapping[str, Any],
        reply_timeout: float,
        reconnect_timeout: float | None,
    ) -> None:
        super().__init__(port, name=name)
        self._asked: dict[str, Any] = {k: v for k, v in given.items() if v is not None}
        self._fixed: dict[str, Any] = dict(fixed)
        self.config = self.config_class.create(**self._asked, **self._fixed)
        self.device = None
        self._setup(self.config, self._new_decoder(self.config), reply_timeout, reconnect_timeout)

    @property
    def decoder(self) -> DecoderT:
        """The decoder fed by this driver (its ``stats`` are the driver's)."""
        return self._decoder

    def _spec(
        self, n_sensors: int, n_markers: int, slot_period_s: float | None = None, **extra: Any
    ) -> StreamSpec:
        """The stream of the current configuration; ``extra`` joins ``config`` in its metadata."""
        return StreamSpec(
            name=self.name,
            kind=self.stream_kind,
            n_sensors=n_sensors,
            n_markers=n_markers,
            rate_hz=self.config.rate_hz,
            tick_hz=self.stream_tick_hz,
            slot_period_s=slot_period_s,
            values=self.values,
            units=self.units,
            metadata={"config": self.config.to_dict(), **extra},
        )

    def _new_decoder(self, config: ConfigT) -> DecoderT:
        decoder: DecoderT = self.decoder_class.from_config(config, stats=self.stats)
        return decoder

    # -- the device's own settings (CONF:) ---------------------------------------------
    def _unasked(self) -> list[str]:
        return [k for k in self.device_keys if k not in self._asked]

    def _device_settings(self, fields: Mapping[str, str]) -> dict[str, Any]:
        try:
            out: dict[str, Any] = {
                key: int(fields[verb]) for verb, key in self.conf_verbs.items() if verb in fields
            }
            if "rate_hz" in out:
                out["rate_hz"] = out["rate_hz"] / 1000
            self._conf_extras(fields, out)
        except ValueError:
            raise ProtocolError(f"{self.port}: CONF reply {fields} has a malformed value") from None
        return out

    def _conf_extras(self, fields: Mapping[str, str], out: dict[str, Any]) -> None:
        """Add to ``out`` the settings of ``fields`` that ``conf_verbs`` does not cover.

        Raises ``ValueError`` on a malformed value (reported as a ``ProtocolError``).
        """

    def _rebuild(self, device: Mapping[str, Any]) -> tuple[ConfigT, DecoderT]:
        config: ConfigT = self.config_class.create(**{**device, **self._asked, **self._fixed})
        return config, self._new_decoder(config)

    # -- the device's VER:0 ----------------------------------------------------------------
    def _check_device(self, reply: Reply) -> None:
        device: VersionT = self.version_class.parse(reply.text)
        self.device = device
        self._check_version(device, reply)

    @abstractmethod
    def _check_version(self, device: VersionT, reply: Reply) -> None:
        """``ConfigurationError`` if ``device`` cannot carry the configuration."""

    @classmethod
    def _device_info(cls, port: str, text: str) -> DeviceInfo:
        version = cls.version_class.parse(text)
        return DeviceInfo(
            family=cls.family,
            port=port,
            description=version.text,
            serial_number=version.serial_number,
            extra={key: getattr(version, key) for key in cls.info_fields},
        )

    # -- discovery -------------------------------------------------------------------
    @classmethod
    def detect(
        cls, ports: Iterable[str | os.PathLike[str]] | None = None, timeout: float = 0.3
    ) -> list[DeviceInfo]:
        """Devices of this family answering on this machine's serial ports.

        Parameters
        ----------
        ports : iterable of str, optional
            Ports or URLs to probe; by default every serial port the OS lists
            with hardware behind it (:func:`~spotlab.drivers.mcs1.discovery.hardware_ports`).
        timeout : float
            Seconds to wait for each port's reset banner and reply.

        Returns
        -------
        list of DeviceInfo
            One per device that answered ``VER:0`` with the family's code. Each probed device
            is left reset (9600 baud, not streaming). Ports that cannot be
            opened (busy, no permission) are skipped.
        """
        return discovery.detect(cls.family_code, cls._device_info, ports, timeout)
