"""Append-only writer of the recording journal.

Records are appended to an in-memory buffer (cheap enough to call from a
device's reader thread for every chunk of bytes) and handed to the operating
system with ``os.write`` on an unbuffered descriptor at least every
``flush_interval_s`` by a small flusher thread. What the OS holds survives a
SIGKILL of the process, so a killed recording loses at most the last
``flush_interval_s`` plus scheduling delay (50 ms by default, <= 100 ms).
``fsync`` (surviving a power cut as well) is optional: periodically and on close.
"""

from __future__ import annotations

import datetime as _dt
import logging
import os
import socket
import threading
import time
import zlib
from collections.abc import Mapping
from importlib import metadata as _importlib_metadata
from pathlib import Path
from types import TracebackType
from typing import Any

from spotlab.core.errors import ConfigurationError, RecordingError
from spotlab.io._journal_format import (
    FORMAT_VERSION,
    MAX_PAYLOAD,
    MAX_STREAMS,
    RECORD_CRC,
    RECORD_HEAD,
    RECORD_MAGIC,
    SESSION_STREAM,
    RecordType,
    encode_file_header,
    encode_json,
    encode_record,
)

log = logging.getLogger(__name__)

_AUTO_SESSION_KEYS = (
    "journal_version",
    "spotlab_version",
    "host",
    "pid",
    "start_time_iso",
    "start_time_ns",
    "start_monotonic_ns",
)


def _spotlab_version() -> str:
    try:
        return _importlib_metadata.version("spotlab")
    except _importlib_metadata.PackageNotFoundError:
        return "unknown"


class JournalWriter:
    """Write a crash-safe journal of raw wire bytes, events and metadata.

    Parameters
    ----------
    path : str or Path
        File to create. Suffix ``.spj`` by convention.
    session_meta : mapping
        JSON-safe description of the session (operator, subject, notes...). The
        writer adds ``journal_version``, ``spotlab_version``, ``host``, ``pid``,
        ``start_time_iso`` (UTC wall clock), ``start_time_ns`` (``time.time_ns``)
        and ``start_monotonic_ns`` (``time.monotonic_ns``, the clock of every
        record stamp); ``session_meta`` may not use those keys.
    overwrite : bool, optional
        Replace an existing file. By default an existing file is never touched.
    flush_interval_s : float, optional
        Longest time a record stays in memory before it is handed to the OS
        (default 0.05 s). What the OS holds survives a kill of the process.
    fsync_interval_s : float, optional
        Also ``fsync`` the file this often (survives a power cut; costs disk
        latency on the flusher thread, never on the callers). ``None``: never
        periodically.
    fsync_on_close : bool, optional
        ``fsync`` when closing (default True).
    max_buffer_bytes : int, optional
        Flush at once when this much is buffered (bounds memory; default 4 MiB).

    Raises
    ------
    RecordingError
        If the file exists (and ``overwrite`` is false) or cannot be created.
    ConfigurationError
        If an argument is out of range or ``session_meta`` uses a reserved key.

    Notes
    -----
    All methods are thread-safe: several reader threads may append at once.
    Always :meth:`close` the writer (or use it as a context manager): it owns a
    flusher thread, and only a closed journal ends with an END record.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        session_meta: Mapping[str, Any] | None = None,
        *,
        overwrite: bool = False,
        flush_interval_s: float = 0.05,
        fsync_interval_s: float | None = None,
        fsync_on_close: bool = True,
        max_buffer_bytes: int = 4 << 20,
    ) -> None:
        if not 0.0 < flush_interval_s <= 1.0:
            raise ConfigurationError(
                f"flush_interval_s must be in (0, 1] s, got {flush_interval_s!r}"
            )
        if fsync_interval_s is not None and not fsync_interval_s > 0:
            raise ConfigurationError(f"fsync_interval_s must be positive, got {fsync_interval_s!r}")
        if max_buffer_bytes < 4096:
            raise ConfigurationError(f"max_buffer_bytes must be >= 4096, got {max_buffer_bytes}")
        meta = dict(session_meta or {})
        clash = sorted(set(meta) & set(_AUTO_SESSION_KEYS))
        if clash:
            raise ConfigurationError(f"session_meta may not set {clash}: the journal writes them")
        self.path = Path(path)
        self._flush_ns = int(flush_interval_s * 1e9)
        self._fsync_interval_s = fsync_interval_s
        self._fsync_on_close = fsync_on_close
        self._max_buffer = max_buffer_bytes
        self._lock = threading.Lock()  # guards the buffer and the stream table
        self._write_lock = threading.Lock()  # keeps os.write calls in buffer order
        self._buf = bytearray()
        self._first_ns = 0  # monotonic time of the oldest buffered record
        self._names: list[str] = []
        self._error: RecordingError | None = None
        self._closed = False
        self._closing = False
        self.bytes_written = 0
        self.records_written = 0

        flags = os.O_WRONLY | os.O_CREAT | (os.O_TRUNC if overwrite else os.O_EXCL)
        try:
            self._fd = os.open(self.path, flags, 0o644)
        except FileExistsError:
            raise RecordingError(
                f"{self.path} already exists; choose another name or pass overwrite=True"
            ) from None
        except OSError as exc:
            raise RecordingError(
                f"cannot create journal {self.path}: {exc.strerror or exc}"
            ) from exc

        wall_ns = time.time_ns()
        self.start_monotonic_ns = time.monotonic_ns()
        self.session: dict[str, Any] = {
            "journal_version": FORMAT_VERSION,
            "spotlab_version": _spotlab_version(),
            "host": socket.gethostname(),
            "pid": os.getpid(),
            "start_time_iso": _dt.datetime.fromtimestamp(wall_ns / 1e9, _dt.UTC).isoformat(),
            "start_time_ns": wall_ns,
            "start_monotonic_ns": self.start_monotonic_ns,
            **meta,
        }
        # The header and the session description go to the OS at once: a
        # journal killed a moment after creation is still recognised as one.
        first = encode_file_header() + encode_record(
            RecordType.META, SESSION_STREAM, self.start_monotonic_ns, encode_json(self.session)
        )
        try:
            self._write_all(first)
        except RecordingError:
            os.close(self._fd)
            raise
        self.records_written = 1
        self._stop = threading.Event()
        self._flusher = threading.Thread(
            target=self._flush_loop, name=f"spotlab-journal-{self.path.name}", daemon=True
        )
        self._flusher.start()

    # -- public API ---------------------------------------------------------
    @property
    def closed(self) -> bool:
        """Whether :meth:`close` has run."""
        return self._closed

    @property
    def streams(self) -> list[str]:
        """Declared stream names, by index."""
        return list(self._names)

    def add_stream(self, name: str, metadata: Mapping[str, Any] | None = None) -> int:
        """Declare a stream and return its index for :meth:`rx`, :meth:`tx`, :meth:`event`.

        Parameters
        ----------
        name : str
            Stream name, unique in this journal.
        metadata : mapping, optional
            JSON-safe facts needed to decode the stream again (driver family,
            ``StreamSpec``, configuration). May be completed later with
            :meth:`update_stream`.

        Raises
        ------
        ConfigurationError
            If the name is empty or already declared, or 65535 streams exist.
        """
        if not name:
            raise ConfigurationError("a journal stream needs a non-empty name")
        with self._lock:
            if name in self._names:
                raise ConfigurationError(f"stream {name!r} is already declared in {self.path}")
            if len(self._names) >= MAX_STREAMS:
                raise ConfigurationError(f"a journal holds at most {MAX_STREAMS} streams")
            index = len(self._names)
            self._names.append(name)
        self._append(
            RecordType.META, index, self._stream_payload(index, metadata), time.monotonic_ns()
        )
        return index

    def update_stream(self, index: int, metadata: Mapping[str, Any]) -> None:
        """Replace the metadata of stream ``index`` from here on (known only after start)."""
        self._check_stream(index)
        self._append(
            RecordType.META, index, self._stream_payload(index, metadata), time.monotonic_ns()
        )

    def rx(self, index: int, data: bytes | bytearray | memoryview, t_ns: int) -> None:
        """Record bytes read from stream ``index``'s device, arrived at ``t_ns`` (monotonic ns)."""
        self._wire(RecordType.RX, index, data, t_ns)

    def tx(self, index: int, data: bytes | bytearray | memoryview, t_ns: int) -> None:
        """Record bytes written to stream ``index``'s device, sent at ``t_ns`` (monotonic ns)."""
        self._wire(RecordType.TX, index, data, t_ns)

    def event(self, index: int, kind: str, detail: Mapping[str, Any] | None, t_ns: int) -> None:
        """Record an event of stream ``index`` (or ``SESSION_STREAM``) at ``t_ns``.

        Parameters
        ----------
        index : int
            Stream index, or ``SESSION_STREAM`` for a session-wide event.
        kind : str
            ``disconnected``, ``reconnected``, ``device_reset``, ``error``,
            ``link_stats``... (replay acts on the first three).
        detail : mapping or None
            JSON-safe facts; values JSON cannot hold are written as text.
        t_ns : int
            Host monotonic time in ns.
        """
        if index != SESSION_STREAM:
            self._check_stream(index)
        payload = encode_json({"kind": str(kind), "detail": dict(detail or {})})
        self._append(RecordType.EVENT, index, payload, t_ns)

    def flush(self) -> None:
        """Hand every buffered record to the OS now.

        Raises
        ------
        RecordingError
            If the OS refuses the write (disk full, I/O error).
        """
        with self._write_lock:
            with self._lock:
                if self._error is not None:
                    raise self._error
                if not self._buf:
                    return
                data, self._buf = self._buf, bytearray()
            self._write_all(data)

    def close(self) -> None:
        """Write the END record, flush, optionally fsync, release the file. Safe to call twice.

        Raises
        ------
        RecordingError
            If a write failed at any time since the last call (the error is raised once).
        """
        with self._lock:
            if self._closing:
                return
            self._closing = True
        self._stop.set()
        if self._flusher is not threading.current_thread():
            self._flusher.join()
        try:
            if self._error is None:
                wall_ns = time.time_ns()
                end = {
                    "stop_time_iso": _dt.datetime.fromtimestamp(wall_ns / 1e9, _dt.UTC).isoformat(),
                    "stop_time_ns": wall_ns,
                    "records": self.records_written + 1,
                }
                record = encode_record(
                    RecordType.END, SESSION_STREAM, time.monotonic_ns(), encode_json(end)
                )
                with self._lock:
                    # END is the last record: from here on appends are refused.
                    self._buf += record
                    self.records_written += 1
                    self._closed = True
                self.flush()
                if self._fsync_on_close:
                    self._fsync()
        finally:
            with self._lock:
                self._closed = True
            os.close(self._fd)
        if self._error is not None:
            raise self._error

    def __enter__(self) -> JournalWriter:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    # -- internals ------------------------------------------------------------
    def _stream_payload(self, index: int, metadata: Mapping[str, Any] | None) -> bytes:
        return encode_json({"name": self._names[index], "metadata": dict(metadata or {})})

    def _check_stream(self, index: int) -> None:
        if not 0 <= index < len(self._names):
            raise ConfigurationError(
                f"stream index {index} is not declared in {self.path} "
                f"(declared: 0 to {len(self._names) - 1})"
            )

    def _wire(
        self, rtype: RecordType, index: int, data: bytes | bytearray | memoryview, t_ns: int
    ) -> None:
        if not 0 <= index < len(self._names):
            self._check_stream(index)
        n = len(data)
        if n <= MAX_PAYLOAD:
            self._append(rtype, index, data, t_ns)
            return
        view = memoryview(data).cast("B")
        for start in range(0, n, MAX_PAYLOAD):
            self._append(rtype, index, view[start : start + MAX_PAYLOAD], t_ns)

    def _append(
        self, rtype: int, index: int, payload: bytes | bytearray | memoryview, t_ns: int
    ) -> None:
        n = len(payload)
        if n > MAX_PAYLOAD:
            raise ConfigurationError(
                f"a {RecordType(rtype).name} record of {n} bytes exceeds {MAX_PAYLOAD} bytes"
            )
        try:
            head = RECORD_HEAD.pack(RECORD_MAGIC, rtype, 0, index, n, t_ns)
        except Exception as exc:  # struct.error: stamp out of int64 range
            raise ConfigurationError(f"timestamp {t_ns!r} is not an int64 of nanoseconds") from exc
        crc = RECORD_CRC.pack(zlib.crc32(payload, zlib.crc32(head)))
        now = time.monotonic_ns()
        with self._lock:
            if self._closed:
                raise RecordingError(f"journal {self.path} is closed")
            if self._error is not None:
                raise self._error
            buf = self._buf
            if not buf:
                self._first_ns = now
            buf += head
            buf += crc
            buf += payload
            self.records_written += 1
            # A backstop for a starved flusher thread: never hold a record for
            # more than two flush intervals, never hold unbounded memory.
            due = len(buf) >= self._max_buffer or now - self._first_ns >= 2 * self._flush_ns
        if due:
            self.flush()

    def _write_all(self, data: bytes | bytearray) -> None:
        view = memoryview(data)
        try:
            while view:
                written = os.write(self._fd, view)
                view = view[written:]
                self.bytes_written += written
        except OSError as exc:
            err = RecordingError(
                f"cannot write journal {self.path}: {exc.strerror or exc}; "
                f"{len(view)} bytes of recording were lost"
            )
            with self._lock:
                self._error = self._error or err
            raise err from exc

    def _fsync(self) -> None:
        try:
            os.fsync(self._fd)
        except OSError as exc:
            err = RecordingError(f"cannot fsync journal {self.path}: {exc.strerror or exc}")
            with self._lock:
                self._error = self._error or err
            raise err from exc

    def _flush_loop(self) -> None:
        last_sync = time.monotonic()
        period = self._flush_ns / 1e9
        while not self._stop.wait(period):
            try:
                self.flush()
                if (
                    self._fsync_interval_s is not None
                    and time.monotonic() - last_sync >= self._fsync_interval_s
                ):
                    self._fsync()
                    last_sync = time.monotonic()
            except RecordingError as exc:
                log.error("%s", exc)
                return
