"""The recorder: every byte on every device link, into a crash-safe journal.

The recorder is a :class:`~spotlab.core.wire.WireTap`: drivers hand it their
raw bytes and link events straight from the reader thread, and it appends
them to the journal's in-memory buffer (flushed by time). It does not record
decoded blocks, so a full sink queue can never cost it a byte, and a recording
can be decoded again by a newer driver. It is also a sink, so a
:class:`~spotlab.acquisition.session.Session` registers it on every device,
writes each stream's metadata once the devices are started, and the final
link statistics when it stops.
"""

from __future__ import annotations

import logging
import os
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from types import TracebackType
from typing import Any

from spotlab.acquisition.interfaces import Device, SinkBase
from spotlab.core.errors import ConfigurationError, RecordingError
from spotlab.core.frames import FrameBlock
from spotlab.core.wire import LinkEventKind
from spotlab.io.journal import SESSION_STREAM, JournalWriter

log = logging.getLogger(__name__)


class Recorder(SinkBase):
    """Record raw wire bytes, link events and stream metadata of a session.

    Parameters
    ----------
    path : str or Path
        Journal to create (``.spj``); an existing file is refused unless
        ``overwrite`` is true.
    session_meta : mapping, optional
        JSON-safe description of the session (operator, subject, notes).
    overwrite : bool, optional
        Replace an existing file.
    flush_interval_s, fsync_interval_s, fsync_on_close
        Durability settings of :class:`~spotlab.io.journal.JournalWriter`.

    Raises
    ------
    RecordingError
        If the journal cannot be created (it exists, no such folder, no permission).

    Notes
    -----
    With a :class:`Session`, pass the recorder as a sink and nothing else.
    Without one::

        recorder.attach(devices)      # before the devices start: catch every byte
        for d in devices: d.start()
        recorder.on_start(devices)    # stream metadata (known after start)
        ...
        for d in devices: d.stop()
        recorder.stop()               # final link statistics, END record

    A failed write (disk full) does not disturb acquisition: the recorder
    logs it, stops writing, exposes it as :attr:`error` and raises it from
    :meth:`stop`.
    """

    name = "recorder"

    def __init__(
        self,
        path: str | os.PathLike[str],
        session_meta: Mapping[str, Any] | None = None,
        *,
        overwrite: bool = False,
        flush_interval_s: float = 0.05,
        fsync_interval_s: float | None = None,
        fsync_on_close: bool = True,
    ) -> None:
        self.path = Path(path)
        self._journal = JournalWriter(
            self.path,
            session_meta,
            overwrite=overwrite,
            flush_interval_s=flush_interval_s,
            fsync_interval_s=fsync_interval_s,
            fsync_on_close=fsync_on_close,
        )
        self._index: dict[str, int] = {}
        self._lock = threading.Lock()
        self._devices: list[Device] = []
        self._stopping = False
        self._raised = False
        self.error: RecordingError | None = None
        """The first write failure, if any (acquisition went on without recording)."""
        self.frames: dict[str, int] = {}
        """Frames seen per stream through ``on_block`` (for reports; bytes are what is kept)."""
        self.late_records = 0
        """Taps that arrived after :meth:`stop` and were not recorded."""
        self.rejected_records = 0
        """Taps refused as malformed (a timestamp outside int64), logged."""

    # -- wiring ----------------------------------------------------------------------
    def attach(self, devices: Sequence[Device]) -> None:
        """Register this recorder as a tap on ``devices`` (without a Session)."""
        for device in devices:
            device.add_tap(self)

    def on_start(self, devices: Sequence[Device]) -> None:
        """Write each device's metadata (``device.metadata()``); devices are started."""
        self._devices = list(devices)
        for device in self._devices:
            try:
                meta = dict(device.metadata())
            except Exception as exc:
                # Keep recording the bytes: they are decodable once the metadata is known.
                log.error("metadata of %s unavailable: %s", device.name, exc)
                meta = {"metadata_error": f"{type(exc).__name__}: {exc}"}
            self._guard(self._declare, device.name, meta)

    # -- WireTap ---------------------------------------------------------------------
    def on_rx(self, stream: str, data: bytes, arrival_ns: int) -> None:
        """Record bytes read from ``stream``'s device."""
        self._guard(self._wire, self._journal.rx, stream, data, arrival_ns)

    def on_tx(self, stream: str, data: bytes, sent_ns: int) -> None:
        """Record bytes written to ``stream``'s device."""
        self._guard(self._wire, self._journal.tx, stream, data, sent_ns)

    def on_event(
        self, stream: str, kind: LinkEventKind, detail: dict[str, object], t_ns: int
    ) -> None:
        """Record a link event of ``stream``."""
        self._guard(self._event, stream, str(kind), detail, t_ns)

    # -- Sink --------------------------------------------------------------------------
    def on_block(self, stream: str, block: FrameBlock) -> None:
        """Count frames (the recording holds the bytes they came from)."""
        self.frames[stream] = self.frames.get(stream, 0) + len(block)

    def on_error(self, stream: str, exc: BaseException) -> None:
        """Record a device error as an ``error`` event of its stream."""
        detail = {"type": type(exc).__name__, "message": str(exc)}
        code = getattr(exc, "code", None)
        if code is not None:
            detail["code"] = code
        self._guard(self._event, stream, "error", detail, time.monotonic_ns())

    def stop(self) -> None:
        """Record final link statistics per stream, write END and close the journal.

        Raises
        ------
        RecordingError
            If any write failed during the recording (raised once).
        """
        with self._lock:
            already = self._stopping
            self._stopping = True
        if not already:
            t_ns = time.monotonic_ns()
            for device in self._devices:
                stats = getattr(device, "stats", None)
                if stats is not None:
                    self._write_event(device.name, "link_stats", stats.as_dict(), t_ns)
            try:
                self._journal.close()
            except RecordingError as exc:
                self._fail(exc)
        if self.error is not None and not self._raised:
            self._raised = True
            raise self.error

    def __enter__(self) -> Recorder:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.stop()

    @property
    def bytes_written(self) -> int:
        """Bytes of journal handed to the OS so far."""
        return self._journal.bytes_written

    # -- internals -----------------------------------------------------------------------
    def _guard(self, write: Callable[..., None], *args: Any) -> None:
        # Called from reader threads: a recording problem must never raise into a driver.
        if self._stopping:
            self.late_records += 1
            return
        if self.error is not None:
            return
        self._write_guarded(write, *args)

    def _write_guarded(self, write: Callable[..., None], *args: Any) -> None:
        try:
            write(*args)
        except RecordingError as exc:
            if self._stopping:
                self.late_records += 1
            else:
                self._fail(exc)
        except ConfigurationError as exc:
            self.rejected_records += 1
            if self.rejected_records <= 3:
                log.error("recorder refused a record: %s", exc)

    def _write_event(self, stream: str, kind: str, detail: Mapping[str, Any], t_ns: int) -> None:
        self._write_guarded(self._event, stream, kind, detail, t_ns)

    def _fail(self, exc: RecordingError) -> None:
        if self.error is None:
            self.error = exc
            log.error("recording stopped: %s", exc)

    def _stream(self, name: str) -> int:
        index = self._index.get(name)
        if index is None:
            with self._lock:
                index = self._index.get(name)
                if index is None:
                    # Bytes of the start-up dialogue come before the metadata.
                    index = self._journal.add_stream(name, {})
                    self._index[name] = index
        return index

    def _declare(self, name: str, meta: dict[str, Any]) -> None:
        with self._lock:
            index = self._index.get(name)
            if index is None:
                self._index[name] = self._journal.add_stream(name, meta)
                return
        self._journal.update_stream(index, meta)

    def _wire(
        self, write: Callable[[int, bytes, int], None], stream: str, data: bytes, t: int
    ) -> None:
        write(self._stream(stream), data, t)

    def _event(self, stream: str, kind: str, detail: Mapping[str, Any] | None, t_ns: int) -> None:
        index = SESSION_STREAM if stream == "" else self._stream(stream)
        self._journal.event(index, kind, detail, t_ns)
