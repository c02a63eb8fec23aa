"""QTM's UDP stream option (``StreamFrames AllFrames UDP:PORT 3D 6D``) against the simulated
QTM: every frame the server sent is recorded, by datagram, equal to the truth; drops are
counted; a reconnection streams by UDP again; bad settings are one error line."""

from __future__ import annotations

import socket
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from spotlab.acquisition.replay import replay
from spotlab.console.cli import main
from spotlab.core.errors import ConfigurationError
from spotlab.core.frames import FrameBlock
from spotlab.drivers.qualisys import QualisysDriver, command_packet
from spotlab.io.journal import JournalReader
from spotlab.processing.decoding import decoder_for
from spotlab.simulators.qualisys import QualisysServer, QualisysSimOptions


def _replayed(path: Path) -> FrameBlock:
    return FrameBlock.concat([b for _, b in replay(path, decoder_for) if len(b)])


def _run(driver: QualisysDriver, seconds: float) -> FrameBlock:
    blocks = []
    driver.start()
    t_end = time.monotonic() + seconds
    while time.monotonic() < t_end:
        b = driver.recv(0.1)
        if b is not None and len(b):
            blocks.append(b)
    driver.stop()
    blocks += driver.drain()
    return FrameBlock.concat(blocks)


def test_record_by_udp_keeps_every_frame_sent(tmp_path: Path, capsys: Any) -> None:
    out = tmp_path / "u.spj"
    options = QualisysSimOptions(markers=12, cameras=4, rate_hz=200.0, seed=3)
    with QualisysServer(options) as server:
        code = main(
            ["record", "--device", f"qualisys={server.address},udp=0", "--seconds", "2",
             "--out", str(out)]
        )  # fmt: skip
    assert code == 0, capsys.readouterr().err
    truth = server.truth()
    block = _replayed(out)
    # every frame QTM sent is in the journal, the last ones included (drained after Stop)
    assert block.seq.tolist() == truth["frame"].tolist()
    assert 380 <= len(block) <= 440
    assert np.array_equal(block.data[:, :, 0, :], truth["markers_mm"].astype(np.float32))
    assert np.array_equal(block.ticks, truth["timestamp_us"])
    reader = JournalReader(out)
    meta = next(iter(reader.streams.values()))
    assert meta["qtm"]["udp_port"] == 0
    events = [r.payload for r in reader if r.type.name == "EVENT"]
    assert any(b'"udp"' in e for e in events)


def test_frames_come_as_datagrams_and_drops_are_counted() -> None:
    options = QualisysSimOptions(markers=4, rate_hz=200.0, faults="drop@0.2:3")
    with QualisysServer(options) as server:
        driver = QualisysDriver(server.address, udp_port=0)
        block = _run(driver, 0.8)
        udp = driver._udp
        driver.close()
    assert udp is not None and udp.datagrams == len(block) and udp.foreign == 0
    assert driver.stats.lost_frames == 3 and driver.stats.gaps == 1
    assert np.count_nonzero(np.diff(block.seq) == 4) == 1
    assert np.count_nonzero(np.diff(block.seq) != 1) == 1


def test_reconnection_streams_by_udp_again() -> None:
    options = QualisysSimOptions(markers=4, rate_hz=100.0, faults="disconnect@0.3:0.2")
    with QualisysServer(options) as server:
        driver = QualisysDriver(server.address, udp_port=0)
        block = _run(driver, 1.5)
        udp = driver._udp
        driver.close()
        assert server.connections >= 2
    assert driver.stats.reconnects == 1
    assert udp is not None and udp.datagrams == len(block)
    jumps = np.flatnonzero(np.diff(block.seq) != 1)
    assert len(jumps) == 1 and block.seq[-1] - block.seq[jumps[0] + 1] > 50


def test_simulator_refuses_a_bad_udp_target() -> None:
    with QualisysServer(QualisysSimOptions(markers=4)) as server:
        with socket.create_connection(("127.0.0.1", server.port), timeout=5) as s:
            s.recv(1024)  # the welcome
            s.sendall(command_packet("StreamFrames AllFrames UDP:0 3D"))
            s.settimeout(5)
            reply = s.recv(1024)
    assert reply[4] == 0 and b"Parse error: UDP:0" in reply  # packet type 0: Error


def test_bad_udp_settings_are_one_error_line(capsys: Any, tmp_path: Path) -> None:
    with pytest.raises(ConfigurationError, match="udp_port must be 0-65535"):
        QualisysDriver("127.0.0.1", udp_port=70000)
    busy = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    busy.bind(("127.0.0.1", 0))
    port = busy.getsockname()[1]
    with QualisysServer(QualisysSimOptions(markers=4)) as server:
        code = main(
            ["record", "--device", f"qualisys={server.address},udp={port}", "--seconds", "1",
             "--out", str(tmp_path / "b.spj")]
        )  # fmt: skip
    busy.close()
    err = capsys.readouterr().err.strip().splitlines()
    assert code != 0 and len(err) == 1
    assert err[0].startswith("spotlab: error:") and f"UDP stream on 127.0.0.1:{port}" in err[0]
