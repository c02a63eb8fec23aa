"""A session of devices and sinks, in the style of python-can's ``Notifier``.

One reader thread per device (``spotlab-reader-<name>``) loops on
``device.recv(timeout)`` and offers every block to every sink through a
bounded queue per sink, each drained by its own dispatcher thread
(``spotlab-sink-<name>``). A slow sink never slows the readers or the other
sinks: when its queue is full the block is dropped *for that sink only* and
counted (:meth:`Session.sink_stats`). Raw bytes are recorded by taps on the
devices (see :class:`~spotlab.acquisition.recorder.Recorder`), never through
these queues, so a recording loses nothing to back-pressure.

A sink with a true ``inline`` attribute (:class:`InlineSink`) is called instead
directly by each reader thread, right after ``recv`` returned: no queue and no
thread hand-off, for latency-critical consumers such as the live pipeline. It
must be quick and thread-safe (several readers may call it at once); its
exceptions are caught, counted in :meth:`Session.sink_stats` and never end the
reader.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from types import TracebackType
from typing import Any

from spotlab.acquisition._channel import SinkChannel, SinkStats
from spotlab.acquisition.interfaces import Device, InlineSink, Sink, SinkBase
from spotlab.acquisition.realtime import check_priority, probe, runs_raised
from spotlab.acquisition.session_status import DeviceErrorRecord, SessionStatus, default_is_fatal
from spotlab.core.errors import ConfigurationError, SpotlabError
from spotlab.core.frames import FrameBlock
from spotlab.core.wire import WireTap

__all__ = [
    "Device",
    "DeviceErrorRecord",
    "InlineSink",
    "Session",
    "SessionStatus",
    "Sink",
    "SinkBase",
    "SinkStats",
    "default_is_fatal",
]

log = logging.getLogger(__name__)


def _is_tap(obj: object) -> bool:
    return all(callable(getattr(obj, m, None)) for m in ("on_rx", "on_tx", "on_event"))


def _sink_names(sinks: Sequence[Sink]) -> list[str]:
    names: list[str] = []
    for sink in sinks:
        base = str(getattr(sink, "name", "") or type(sink).__name__)
        name, k = base, 2
        while name in names:
            name, k = f"{base}#{k}", k + 1
        names.append(name)
    return names


class Session:
    """Read several devices at once and feed their blocks to sinks.

    Parameters
    ----------
    devices : sequence of Device
        Devices with distinct names. The session starts and stops them.
    sinks : sequence of Sink
        Consumers. A sink that is also a :class:`~spotlab.core.wire.WireTap`
        (the recorder) is registered on every device with ``add_tap`` at
        :meth:`start`; do not register it yourself as well.
    queue_size : int, optional
        Blocks that may wait for each sink (default 256); more are dropped
        for that sink and counted.
    recv_timeout_s : float, optional
        Timeout of each ``recv`` call (default 0.1 s): how quickly readers see
        :meth:`stop`.
    is_fatal : callable, optional
        Decides whether a device error ends its reader (default
        :func:`default_is_fatal`). Every error is recorded and delivered to
        the sinks' ``on_error`` either way.
    close_devices : bool, optional
        Also ``close()`` the devices when the session stops (default False:
        whoever created them closes them).
    realtime_priority : int, optional
        Run every reader and dispatcher thread under ``SCHED_FIFO`` at this priority
        (1-99) where the system allows it (root, ``CAP_SYS_NICE`` or ``rtprio``), so
        that other programs on the machine do not delay them
        (:mod:`spotlab.acquisition.realtime`, docs/live.md). A refusal leaves the
        threads at the normal policy; :attr:`realtime_refused` says why. Default None:
        the normal policy.

    Raises
    ------
    ConfigurationError
        If there is no device, two devices share a name, ``queue_size`` < 1 or
        ``realtime_priority`` is outside 1-99.

    Examples
    --------
    >>> with Session([camera, timer], [recorder, monitor]) as session:  # doctest: +SKIP
    ...     session.run_for(10.0, progress=print)
    """

    def __init__(
        self,
        devices: Sequence[Device],
        sinks: Sequence[Sink] = (),
        queue_size: int = 256,
        *,
        recv_timeout_s: float = 0.1,
        is_fatal: Callable[[BaseException], bool] = default_is_fatal,
        close_devices: bool = False,
        realtime_priority: int | None = None,
    ) -> None:
        self.devices = list(devices)
        self.sinks = list(sinks)
        if not self.devices:
            raise ConfigurationError("a session needs at least one device")
        names = [d.name for d in self.devices]
        dupes = sorted({n for n in names if names.count(n) > 1})
        if dupes:
            raise ConfigurationError(f"device names must be unique in a session: {dupes} repeat")
        if queue_size < 1:
            raise ConfigurationError(f"queue_size must be at least 1, got {queue_size}")
        if not recv_timeout_s > 0:
            raise ConfigurationError(f"recv_timeout_s must be positive, got {recv_timeout_s}")
        self._recv_timeout = recv_timeout_s
        self._is_fatal = is_fatal
        self._close_devices = close_devices
        self._realtime = check_priority(realtime_priority)
        #: Why a thread could not have ``realtime_priority`` (None: every thread has it,
        #: or none was asked for).
        self.realtime_refused: str | None = None
        self._channels = [SinkChannel(n, queue_size) for n in _sink_names(self.sinks)]
        # Inline sinks: called by the readers, one lock each for their counters.
        self._inline = [
            (sink, channel, threading.Lock())
            for sink, channel in zip(self.sinks, self._channels, strict=True)
            if getattr(sink, "inline", False) is True
        ]
        inline_ids = {id(channel) for _, channel, _ in self._inline}
        self._queued = [c for c in self._channels if id(c) not in inline_ids]
        self._frames = dict.fromkeys(names, 0)
        self._errors: deque[DeviceErrorRecord] = deque(maxlen=1000)
        self._n_errors = 0
        self._lock = threading.Lock()
        self._state = "new"
        self._stop_event = threading.Event()
        self._started: list[Device] = []
        self._readers: list[threading.Thread] = []
        self._dispatchers: list[threading.Thread] = []
        self._t0 = time.monotonic()
        self._target_s: float | None = None
        self._t_stop: float | None = None

    # -- life cycle -------------------------------------------------------------
    def start(self) -> None:
        """Register taps, start the devices, call sinks' ``on_start``, start the threads.

        If anything fails, whatever was started is stopped again and the error
        is raised.

        Raises
        ------
        ConfigurationError
            If the session was already started (a session runs once).
        """
        with self._lock:
            if self._state != "new":
                raise ConfigurationError(f"a session runs once; this one is {self._state}")
            self._state = "starting"
        if self._realtime is not None:
            self.realtime_refused = probe(self._realtime)
            if self.realtime_refused is not None:
                log.warning("%s", self.realtime_refused)
                self._realtime = None  # the threads stay at the normal policy
        try:
            for sink in self.sinks:
                if _is_tap(sink):
                    tap: WireTap = sink  # type: ignore[assignment]
                    for device in self.devices:
                        device.add_tap(tap)
            for device in self.devices:
                device.start()
                self._started.append(device)
            for sink in self.sinks:
                hook = getattr(sink, "on_start", None)
                if callable(hook):
                    hook(list(self.devices))
            for sink, channel in zip(self.sinks, self._channels, strict=True):
                if channel not in self._queued:
                    continue
                self._spawn(
                    self._dispatchers, self._dispatch, (sink, channel), channel.name, "sink"
                )
            self._t0 = time.monotonic()
            for device in self.devices:
                self._spawn(self._readers, self._read, (device,), device.name, "reader")
        except BaseException:
            self._shutdown(raise_errors=False)
            raise
        with self._lock:
            if self._state == "starting":  # not stopped meanwhile by another thread
                self._state = "running"

    def stop(self) -> None:
        """Stop readers and devices, deliver what is queued, join every thread, stop sinks.

        Safe to call twice. Errors raised by devices' ``stop``/``close`` and
        sinks' ``stop`` do not interrupt the shutdown; the first is raised at
        the end (a recorder that could not write raises here).
        """
        self._shutdown(raise_errors=True)

    def request_stop(self) -> None:
        """Ask :meth:`run_for` to end soon; safe from a signal handler or another thread
        (it only sets an event; :meth:`run_for` then stops the session as usual)."""
        self._stop_event.set()

    def __enter__(self) -> Session:
        self.start()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        # An error in the body is the one worth seeing; don't mask it.
        self._shutdown(raise_errors=exc is None)

    def run_for(
        self,
        seconds: float,
        progress: Callable[[SessionStatus], Any] | None = None,
        *,
        progress_interval_s: float = 0.5,
    ) -> SessionStatus:
        """Run for ``seconds`` (starting if needed), then stop.

        Parameters
        ----------
        seconds : float
            How long to acquire.
        progress : callable, optional
            Called with a :class:`SessionStatus` every ``progress_interval_s``
            and once at the end, from the calling thread.
        progress_interval_s : float, optional
            Seconds between progress calls (default 0.5).

        Returns
        -------
        SessionStatus
            The state at the end, after every block was delivered.

        Notes
        -----
        Ends early when every reader thread has ended (fatal errors) or
        another thread calls :meth:`stop`.
        """
        if self._state == "new":
            self.start()
        self._target_s = float(seconds)
        end = time.monotonic() + seconds
        try:
            while True:
                remaining = end - time.monotonic()
                if remaining <= 0 or not any(t.is_alive() for t in self._readers):
                    break
                if self._stop_event.wait(min(progress_interval_s, remaining)):
                    break
                if progress is not None:
                    progress(self.status())
        finally:
            self.stop()
        final = self.status()
        if progress is not None:
            progress(final)
        return final

    # -- what happened ------------------------------------------------------------
    def status(self) -> SessionStatus:
        """A snapshot of frames, overflows and errors."""
        return SessionStatus(
            elapsed_s=0.0
            if self._state == "new"
            else (self._t_stop or time.monotonic()) - self._t0,
            target_s=self._target_s,
            frames=dict(self._frames),
            overflows=self.overflows,
            errors=self._n_errors,
            readers_alive=sum(t.is_alive() for t in self._readers),
        )

    @property
    def frames(self) -> dict[str, int]:
        """Frames received per stream."""
        return dict(self._frames)

    @property
    def overflows(self) -> dict[str, int]:
        """Blocks dropped per sink because its queue was full."""
        return {c.name: c.overflows for c in self._channels}

    def sink_stats(self) -> dict[str, SinkStats]:
        """Delivery counters per sink."""
        return {c.name: c.stats() for c in self._channels}

    @property
    def errors(self) -> list[DeviceErrorRecord]:
        """Device errors, oldest first (the last 1000)."""
        with self._lock:
            return list(self._errors)

    # -- threads ----------------------------------------------------------------------
    def _spawn(
        self,
        into: list[threading.Thread],
        target: Callable[..., None],
        args: tuple[Any, ...],
        name: str,
        role: str,
    ) -> None:
        thread = threading.Thread(
            target=runs_raised(target, self._realtime, self._refused),
            args=args,
            name=f"spotlab-{role}-{name}",
            daemon=True,
        )
        into.append(thread)
        thread.start()

    def _refused(self, why: str) -> None:
        if self.realtime_refused is None:
            self.realtime_refused = why
            log.warning("%s", why)

    def _read(self, device: Device) -> None:
        name = device.name
        stop = self._stop_event
        channels = self._queued
        inline = self._inline
        while not stop.is_set():
            try:
                block = device.recv(timeout=self._recv_timeout)
            except Exception as exc:
                fatal = bool(self._is_fatal(exc))
                self._note_error(name, exc, fatal)
                for sink, channel, lock in inline:
                    self._call_inline(sink.on_error, name, exc, channel, lock, error=True)
                for channel in channels:
                    channel.put_error(name, exc)
                if fatal:
                    log.error("device %s stopped on a fatal error: %s", name, exc)
                    return
                stop.wait(self._recv_timeout)  # do not spin on a failing device
                continue
            if block is None or not len(block):
                continue
            self._deliver(name, block)

    def _deliver(self, name: str, block: FrameBlock) -> None:
        """Hand one block of device ``name`` to every sink."""
        self._frames[name] += len(block)
        for sink, channel, lock in self._inline:
            self._call_inline(sink.on_block, name, block, channel, lock, error=False)
        for channel in self._queued:
            channel.put_block(name, block)

    @staticmethod
    def _call_inline(
        call: Callable[[str, Any], None],
        stream: str,
        payload: Any,
        channel: SinkChannel,
        lock: threading.Lock,
        *,
        error: bool,
    ) -> None:
        """Deliver to an inline sink in the reader's thread; its exceptions are counted."""
        try:
            call(stream, payload)
        except Exception as exc:
            if channel.failures.add(exc):  # the first of its kind: counted all the same
                log.exception("inline sink %s failed on a %s item", channel.name, stream)
        with lock:
            if error:
                channel.errors_delivered += 1
            else:
                channel.delivered += 1

    def _note_error(self, stream: str, exc: BaseException, fatal: bool) -> None:
        with self._lock:
            self._errors.append(DeviceErrorRecord(stream, exc, time.monotonic_ns(), fatal))
            self._n_errors += 1
        if not isinstance(exc, SpotlabError):
            log.warning("device %s raised %r", stream, exc)

    def _dispatch(self, sink: Sink, channel: SinkChannel) -> None:
        while (item := channel.get()) is not None:
            stream, payload = item
            try:
                if isinstance(payload, BaseException):
                    channel.errors_delivered += 1
                    sink.on_error(stream, payload)
                else:
                    channel.delivered += 1
                    sink.on_block(stream, payload)
            except Exception as exc:
                if channel.failures.add(exc):  # the first of its kind: counted all the same
                    log.exception("sink %s failed on a %s item", channel.name, stream)

    def _shutdown(self, *, raise_errors: bool) -> None:
        with self._lock:
            if self._state in ("stopping", "stopped"):
                return
            self._state = "stopping"
        errors: list[BaseException] = []
        self._stop_event.set()
        self._t_stop = time.monotonic()
        me = threading.current_thread()
        for thread in self._readers:
            if thread is not me:
                thread.join(timeout=10 * self._recv_timeout + 5.0)
                if thread.is_alive():
                    errors.append(
                        ConfigurationError(f"{thread.name} did not return from recv; left running")
                    )
        for device in self._started:
            self._collect(errors, device.stop)
            # Frames that arrived before the device's reply to its stop command: the
            # recording holds them, so the sinks get them too (live equals replay).
            drain = getattr(device, "drain", None)
            for block in drain() if callable(drain) else ():
                if len(block):
                    self._deliver(device.name, block)
        for channel in self._channels:
            channel.close()
        for thread in self._dispatchers:
            if thread is not me:
                thread.join()
        if self._close_devices:
            for device in self.devices:
                self._collect(errors, device.close)
        for sink in self.sinks:
            self._collect(errors, sink.stop)
        with self._lock:
            self._state = "stopped"
        for extra in errors[1:]:
            log.error("also while stopping the session: %s", extra)
        if errors and raise_errors:
            raise errors[0]
        if errors:
            log.error("while stopping the session: %s", errors[0])

    @staticmethod
    def _collect(errors: list[BaseException], call: Callable[[], Any]) -> None:
        try:
            call()
        except Exception as exc:
            errors.append(exc)
