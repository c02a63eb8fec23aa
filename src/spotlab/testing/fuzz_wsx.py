"""The WSX fuzz targets of :mod:`spotlab.testing.fuzz`: the frame decoder and the
control-reply parsers the driver uses (docs/protocols/wsx.md).

``wsx``
    The bulk and interrupt bytes of 0.4 s recorded by :class:`WsxDriver` from a
    simulated hub served in this process (2 position sensors, 5 markers, a stall and
    a short packet among them, so that events and a cut frame are in the corpus),
    fed in random reads to :class:`~spotlab.drivers.wsx.decoding.WsxDecoder` built
    from the recorded metadata, with a discontinuity now and then; half the inputs
    have their frames' CRCs made good after the damage, so that damaged headers and
    records get past the CRC check into the decoding. It must never
    raise, every block must have the stream's shape, and ``seq`` must never go back.
``wsx-ctl``
    The replies the driver reads on EP 0 (``INFO``, ``GET_SETUP``, ``STATUS`` and
    every sensor's ``CALIBRATION``), as the simulated hub sends them, each input given
    to every parser the driver uses on them (:meth:`Info.decode`, :meth:`Setup.decode`,
    :meth:`Status.decode`, :func:`parse_calibration` for the sensor its first byte
    names): each returns or raises :class:`~spotlab.core.errors.ProtocolError`.
"""

from __future__ import annotations

import json
import random
import zlib
from collections.abc import Callable
from pathlib import Path
from typing import Any

__all__ = ["control_corpus", "control_run", "frames_corpus", "frames_run"]

_MARKERS, _SENSORS = 5, 2
Run = Callable[[bytes, random.Random], None]


def frames_corpus(folder: Path) -> list[bytes]:
    """0.4 s of a simulated hub's transfers, recorded; the metadata kept in ``folder``."""
    from spotlab.acquisition.recorder import Recorder
    from spotlab.acquisition.session import Session
    from spotlab.drivers.wsx import WsxDriver
    from spotlab.io._journal_format import RecordType
    from spotlab.io.journal import JournalReader
    from spotlab.simulators.wsx_service import WsxSimOptions, serve_wsx

    options = WsxSimOptions(
        sensors=_SENSORS, markers=_MARKERS, rate_hz=200.0, faults="stall@0.1,short@0.2"
    )
    server = serve_wsx(options)
    journal = folder / "wsx.spj"
    try:
        driver = WsxDriver(server.address)
        with Session([driver], [Recorder(journal)], close_devices=True) as session:
            session.run_for(0.4)
    finally:
        server.stop()
    reader = JournalReader(journal)
    meta = next(iter(reader.streams.values()))
    (folder / "wsx.meta.json").write_text(json.dumps(meta))
    rx = b"".join(r.payload for r in reader if r.type == RecordType.RX)
    return [rx, rx[len(rx) // 2 :]]


def frames_run(folder: Path, corpus: list[bytes]) -> Run:
    """Feed an input to a fresh decoder in random reads; check shape and order."""
    from spotlab.drivers.wsx import decoder_from_metadata

    meta = json.loads((folder / "wsx.meta.json").read_text())

    def run(data: bytes, rng: random.Random) -> None:
        decoder = decoder_from_metadata(meta)
        if rng.random() < 0.5:
            data = _resealed(data, decoder.size)
        shape = (decoder.n_markers, 3 * decoder.n_sensors, 3)
        last = -1
        pos = t = 0
        while pos < len(data):
            step = rng.choice((1, 7, 16, 92, 512, 4096, 1 << 16))
            t += 1_000_000
            block = decoder.feed(data[pos : pos + step], t)
            pos += step
            if block.data.shape[1:] != shape:
                raise AssertionError(f"block of shape {block.data.shape}, not (F, {shape})")
            if len(block):
                seq = block.seq
                if seq[0] <= last or bool((seq[1:] <= seq[:-1]).any()):
                    raise AssertionError(f"seq went back: {last} then {seq.tolist()}")
                last = int(seq[-1])
            if rng.random() < 0.05:
                decoder.mark_discontinuity()

    return run


def _resealed(data: bytes, size: int) -> bytes:
    """``data`` with the CRC of every ``WSXF`` of the stream's length made good again,
    so that damaged headers and records reach the decoding past the CRC check."""
    out = bytearray(data)
    at = out.find(b"WSXF")
    while at >= 0 and at + size <= len(out):
        if int.from_bytes(out[at + 4 : at + 8], "little") == size:
            crc = zlib.crc32(bytes(out[at : at + size - 4]))
            out[at + size - 4 : at + size] = crc.to_bytes(4, "little")
        at = out.find(b"WSXF", at + 1)
    return bytes(out)


def control_corpus(folder: Path) -> list[bytes]:
    """The EP 0 replies of a simulated hub with 3 position sensors."""
    from spotlab.drivers.wsx import usbio
    from spotlab.drivers.wsx.protocol import CALIBRATION, GET_SETUP, INFO, STATUS
    from spotlab.simulators.wsx_service import WsxSimOptions, serve_wsx

    server = serve_wsx(WsxSimOptions(sensors=3, markers=4))
    dev: Any = None
    try:
        dev, _ = usbio.open_hub(usbio.parse_port(server.address), "wsx")

        def ask(request: int, length: int, index: int = 0) -> bytes:
            return bytes(dev.ctrl_transfer(0xC0, request, 0, index, length, 1000))

        replies = [ask(INFO, 16), ask(GET_SETUP, 32), ask(STATUS, 16)]
        replies += [ask(CALIBRATION, 188, s) for s in range(3)]
    finally:
        usbio.release(dev)
        server.stop()
    return replies


def control_run(folder: Path, corpus: list[bytes]) -> Run:
    """Give an input to every reply parser; if all refuse it, raise the last refusal."""
    from spotlab.core.errors import ProtocolError
    from spotlab.drivers.wsx.protocol import Info, Setup, Status, error_text, parse_calibration

    def run(data: bytes, rng: random.Random) -> None:
        sensor = data[0] if data else 0
        parsers: list[Callable[[], object]] = [
            lambda: Info.decode(data),
            lambda: Setup.decode(data),
            lambda: error_text(Status.decode(data).last_error),
            lambda: json.dumps(parse_calibration(data, sensor)),
        ]
        refused: list[ProtocolError] = []
        for parse in parsers:
            try:
                parse()
            except ProtocolError as exc:
                refused.append(exc)
        if len(refused) == len(parsers):
            raise refused[-1]

    return run
