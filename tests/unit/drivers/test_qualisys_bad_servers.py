"""Servers that do not behave as QTM does, met by ``spotlab record``: one ``spotlab: error:``
line naming the cause each (refused control, a malformed packet, parameters without the 3D
component); a malformed Data packet in the stream is counted, and the frames around it kept."""

from __future__ import annotations

import json
import socket
import struct
import threading
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from spotlab.acquisition.replay import replay
from spotlab.console.cli import main
from spotlab.core.frames import FrameBlock
from spotlab.processing.decoding import decoder_for
from spotlab.simulators import qualisys_wire as qw
from spotlab.simulators.qualisys import QualisysServer, QualisysSimOptions

GENERAL = "<General><Frequency>100</Frequency></General>"


def _xml(body: str) -> str:
    return f'<?xml version="1.0"?><QTM_Parameters_Ver_1.25>{body}</QTM_Parameters_Ver_1.25>'


Script = Callable[[socket.socket], None]


def _commands(conn: socket.socket) -> Iterator[str]:
    """The client's commands, one at a time."""
    reader = qw.CommandReader()
    while True:
        data = conn.recv(4096)
        if not data:
            return
        for packet in reader.feed(data):
            yield packet.text


@pytest.fixture
def fake_qtm() -> Iterator[Callable[[Script], str]]:
    """A one-connection TCP server running ``script`` on its connection: its address."""
    servers: list[tuple[socket.socket, threading.Thread]] = []

    def start(script: Script) -> str:
        srv = socket.create_server(("127.0.0.1", 0))

        def serve() -> None:
            try:
                conn, _ = srv.accept()
            except OSError:
                return
            with conn:
                try:
                    script(conn)
                except OSError:
                    pass

        thread = threading.Thread(target=serve, daemon=True)
        thread.start()
        servers.append((srv, thread))
        return f"127.0.0.1:{srv.getsockname()[1]}"

    yield start
    for srv, thread in servers:
        srv.close()
        thread.join(5)


def _dialogue(parameters: str, *, control: str | None = None) -> Script:
    """QTM's welcome, version and parameters; ``control``: the reply to TakeControl."""

    def script(conn: socket.socket) -> None:
        conn.sendall(qw.text_packet(qw.COMMAND, "QTM RT Interface connected"))
        for text in _commands(conn):
            verb = text.split()[0].lower()
            if verb == "version":
                conn.sendall(qw.text_packet(qw.COMMAND, "Version set to 1.25"))
            elif verb == "getparameters":
                conn.sendall(qw.text_packet(qw.XML, parameters))
            elif verb == "takecontrol":
                conn.sendall(qw.text_packet(qw.ERROR, control or "Parse error"))

    return script


def _record(address: str, tmp_path: Path, extra: str = "") -> None:
    code = main(
        ["record", "--device", f"qualisys={address}{extra}", "--seconds", "1", "--out",
         str(tmp_path / "x.spj")]
    )  # fmt: skip
    assert code != 0


def _one_line(capsys: Any) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("spotlab: error:"), err
    return err[0]


def test_control_refused_is_one_line(fake_qtm: Any, tmp_path: Path, capsys: Any) -> None:
    labels = "<The_3D><Label><Name>A</Name></Label></The_3D>"
    address = fake_qtm(_dialogue(_xml(GENERAL + labels), control="The client is already master"))
    _record(address, tmp_path, ",password=pw")
    line = _one_line(capsys)
    assert "refused TakeControl" in line and "already master" in line


def test_parameters_without_3d_are_one_line(fake_qtm: Any, tmp_path: Path, capsys: Any) -> None:
    address = fake_qtm(_dialogue(_xml(GENERAL)))
    _record(address, tmp_path)
    assert "has no labelled markers" in _one_line(capsys)


def test_a_malformed_header_is_one_line(fake_qtm: Any, tmp_path: Path, capsys: Any) -> None:
    def script(conn: socket.socket) -> None:
        conn.sendall(struct.pack("<II", 3, 99) + b"garbage")
        conn.recv(1024)

    _record(fake_qtm(script), tmp_path)
    assert "sent a header no QTM sends" in _one_line(capsys)


def test_a_malformed_data_packet_is_counted_and_the_rest_kept(tmp_path: Path, capsys: Any) -> None:
    """The simulator's stream with one Data packet cut short in the middle (its size field
    left whole): the decoder counts it and keeps every other frame."""
    out = tmp_path / "m.spj"
    options = QualisysSimOptions(markers=6, rate_hz=100.0, seed=1)
    with QualisysServer(options) as server:
        original = server._data
        served: list[int] = []

        def data(n: int, frame: Any, components: tuple[str, ...]) -> bytes:
            packet = original(n, frame, components)
            served.append(n)
            if (
                n == served[0] + 40
            ):  # the 3D component's size field claims more than the packet holds
                return packet[:24] + struct.pack("<I", 10_000) + packet[28:]
            return packet

        server._data = data  # type: ignore[method-assign]
        code = main(
            ["record", "--device", f"qualisys={server.address}", "--seconds", "1.5", "--out",
             str(out)]
        )  # fmt: skip
    assert code == 0
    truth = server.truth()
    n_bad = served[0] + 40
    block = FrameBlock.concat([b for _, b in replay(out, decoder_for) if len(b)])
    sent = [int(f) for f in truth["frame"] if f != n_bad]
    assert n_bad in truth["frame"].tolist() and block.seq.tolist() == sent
    rows = [i for i, f in enumerate(truth["frame"]) if f != n_bad]
    assert np.array_equal(block.data[:, :, 0, :], truth["markers_mm"][rows].astype(np.float32))
    capsys.readouterr()
    assert main(["info", str(out), "--json"]) == 0
    (stream,) = json.loads(capsys.readouterr().out)["streams"]
    assert stream["device_summary"]["malformed"] == 1 and stream["crc_errors"] == 1
    assert stream["lost_frames"] == 1 and stream["frames"] == len(sent)
