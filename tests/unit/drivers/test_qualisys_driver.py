"""The QTM driver end to end against the simulated QTM: ``spotlab record`` of 5 s keeps every
frame, the journal decodes to the simulator's truth and to what Qualisys' own client (qtm-rt)
decodes of the same frames; a refused version, the password flow, dropped frames and a
disconnect with reconnection."""

from __future__ import annotations

import asyncio
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from spotlab.acquisition.replay import replay
from spotlab.console.cli import main
from spotlab.core.errors import DeviceError
from spotlab.core.frames import FrameBlock
from spotlab.drivers.qualisys import QualisysDriver, bodies_from_recording
from spotlab.io import TRIAL_READERS
from spotlab.processing.decoding import decoder_for
from spotlab.simulators.qualisys import QualisysServer, QualisysSimOptions


def _vendor_client(
    port: int, stop: threading.Event, out: dict[int, tuple[np.ndarray, np.ndarray]]
) -> threading.Thread:
    """Qualisys' qtm-rt client streaming 3D and 6D in a thread of its own until ``stop`` is
    set: frame -> (markers (M, 3), bodies (B, 12) as sent)."""
    qtm_rt = pytest.importorskip("qtm_rt")

    def on_packet(p: Any) -> None:
        _, markers = p.get_3d_markers()
        _, bodies = p.get_6d()
        six = np.array([[b[0].x, b[0].y, b[0].z, *b[1].matrix] for b in bodies])
        out[p.framenumber] = (np.array([[m.x, m.y, m.z] for m in markers]), six)

    async def session() -> None:
        conn = await qtm_rt.connect("127.0.0.1", port=port)
        await conn.stream_frames(components=["3d", "6d"], on_packet=on_packet)
        while not stop.is_set():
            await asyncio.sleep(0.05)
        await conn.stream_frames_stop()
        conn.disconnect()

    thread = threading.Thread(target=asyncio.run, args=(session(),), daemon=True)
    thread.start()
    return thread


def _replayed(path: Path) -> FrameBlock:
    blocks = [b for _, b in replay(path, decoder_for) if len(b)]
    return FrameBlock.concat(blocks)


def test_record_5_s_equals_truth_and_vendor_client(tmp_path: Path, capsys: Any) -> None:
    out = tmp_path / "q.spj"
    options = QualisysSimOptions(markers=40, cameras=4, rate_hz=100.0, seed=2)
    vendor: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    stop = threading.Event()
    with QualisysServer(options) as server:
        client = _vendor_client(server.port, stop, vendor)
        code = main(
            ["record", "--device", f"qualisys={server.address}", "--seconds", "5", "--out",
             str(out)]
        )  # fmt: skip
        stop.set()
        client.join(10)
    assert code == 0, capsys.readouterr().err
    truth = server.truth()
    block = _replayed(out)
    assert 480 <= len(block) <= 520
    assert np.all(np.diff(block.seq) == 1)  # every frame kept
    row = {int(n): i for i, n in enumerate(truth["frame"])}
    rows = [row[int(s)] for s in block.seq]
    assert np.array_equal(block.ticks, truth["timestamp_us"][rows])
    true32 = truth["markers_mm"][rows].astype(np.float32)
    assert np.array_equal(block.data[:, :, 0, :], true32)
    both = [i for i, s in enumerate(block.seq) if int(s) in vendor]
    assert len(both) == len(block)  # the client saw every frame recorded
    theirs = np.array([vendor[int(block.seq[i])][0] for i in both])
    assert np.array_equal(block.data[both, :, 0, :], theirs)
    bodies = bodies_from_recording(out)
    assert bodies.names == ("pelvis", "head", "thorax")
    assert np.array_equal(bodies.seq, block.seq)
    assert np.array_equal(bodies.positions, truth["body_positions_mm"][rows].astype(np.float32))
    assert np.abs(bodies.rotations - truth["body_rotations"][rows]).max() < 1e-6
    their6 = np.array([vendor[int(s)][1] for s in bodies.seq])
    assert np.array_equal(their6[:, :, :3], bodies.positions)
    assert np.array_equal(
        their6[:, :, 3:], bodies.rotations.transpose(0, 1, 3, 2).reshape(-1, 3, 9)
    )
    code = main(["info", str(out), "--json"])
    assert code == 0
    info = capsys.readouterr().out.strip().splitlines()[-1]
    assert '"lost_frames": 0' in info and '"name": "qualisys"' in info


def test_labels_and_bodies_in_the_recording(tmp_path: Path) -> None:
    with QualisysServer(QualisysSimOptions(markers=12, rate_hz=50.0)) as server:
        driver = QualisysDriver(server.address)
        driver.start()
        try:
            got = None
            while got is None:
                got = driver.recv(2.0)
        finally:
            driver.close()
    meta = driver.metadata()
    assert meta["spec"]["metadata"]["marker_labels"] == list(server.scene.labels)
    assert meta["qtm"]["rate_hz"] == 50.0 and meta["spec"]["rate_hz"] == 50.0
    assert meta["spec"]["kind"] == "point3d" and meta["spec"]["n_markers"] == 12
    assert meta["spec"]["metadata"]["bodies"] == []  # the first 12 labels hold no cluster


def test_version_refused_is_one_error_line(capsys: Any, tmp_path: Path) -> None:
    options = QualisysSimOptions(markers=4, versions=("1.19",))
    with QualisysServer(options) as server:
        code = main(
            ["record", "--device", f"qualisys={server.address}", "--seconds", "1", "--out",
             str(tmp_path / "x.spj")]
        )  # fmt: skip
    err = capsys.readouterr().err.strip().splitlines()
    assert code != 0
    assert len(err) == 1 and err[0].startswith("spotlab: error:"), err
    assert "1.25" in err[0] and "Version NOT supported" in err[0]


def test_password_flow() -> None:
    with QualisysServer(QualisysSimOptions(markers=4, password="pw")) as server:
        wrong = QualisysDriver(server.address, password="nope")
        with pytest.raises(DeviceError, match="Wrong or missing password"):
            wrong.start()
        wrong.close()
        right = QualisysDriver(server.address, password="pw")
        right.start()
        assert right.recv(2.0) is not None
        right.close()


def test_dropped_frames_are_counted() -> None:
    with QualisysServer(QualisysSimOptions(markers=4, rate_hz=200, faults="drop@0.2:3")) as server:
        driver = QualisysDriver(server.address)
        driver.start()
        blocks = []
        t_end = time.monotonic() + 0.6
        while time.monotonic() < t_end:
            b = driver.recv(0.1)
            if b is not None:
                blocks.append(b)
        driver.close()
    seq = FrameBlock.concat(blocks).seq
    assert driver.stats.lost_frames == 3 and driver.stats.gaps == 1
    assert np.count_nonzero(np.diff(seq) == 4) == 1


def test_disconnect_and_reconnect(tmp_path: Path) -> None:
    out = tmp_path / "d.spj"
    options = QualisysSimOptions(markers=6, rate_hz=100.0, faults="disconnect@1:0.3")
    with QualisysServer(options) as server:
        code = main(
            ["record", "--device", f"qualisys={server.address}", "--seconds", "3", "--out",
             str(out)]
        )  # fmt: skip
        assert server.connections >= 2
    assert code == 0
    truth = server.truth()
    block = _replayed(out)
    jumps = np.flatnonzero(np.diff(block.seq) != 1)
    assert len(jumps) == 1  # the outage, nothing else
    outage = block.seq[jumps[0] + 1] - block.seq[jumps[0]]
    assert 20 <= outage <= 100  # 0.3 s at 100 Hz and the retries
    row = {int(n): i for i, n in enumerate(truth["frame"])}
    rows = [row[int(s)] for s in block.seq]
    assert np.array_equal(block.data[:, :, 0, :], truth["markers_mm"][rows].astype(np.float32))
    assert 150 <= len(block) <= 300
    # spotlab export --c3d: the labelled markers as they are, the outage as NaN rows
    c3d = tmp_path / "d.c3d"
    assert main(["export", str(out), "--c3d", str(c3d)]) == 0
    trial = TRIAL_READERS[".c3d"](c3d)
    assert trial.labels == list(server.scene.labels) and trial.point_rate == 100.0
    assert trial.n_frames == block.seq[-1] - block.seq[0] + 1
    kept = block.seq - block.seq[0]
    assert np.allclose(trial.points[kept], block.data[:, :, 0, :], atol=1e-3)
    assert np.isnan(trial.points[jumps[0] + 1 : jumps[0] + outage]).all()


def test_capture_events_reach_the_decoder() -> None:
    import socket

    from spotlab.drivers.qualisys import command_packet

    with QualisysServer(QualisysSimOptions(markers=4)) as server:
        driver = QualisysDriver(server.address)
        driver.start()
        with socket.create_connection(("127.0.0.1", server.port), timeout=5) as other:
            other.sendall(command_packet("TakeControl") + command_packet("Start"))
            t_end = time.monotonic() + 0.5
            while time.monotonic() < t_end:
                driver.recv(0.1)
            other.sendall(command_packet("Stop"))
            t_end = time.monotonic() + 0.3
            while time.monotonic() < t_end:
                driver.recv(0.1)
        driver.close()
    names = [name for _, _, name in driver.decoder.events]
    assert names == ["capture started", "capture stopped"]
    assert driver.decoder.summary()["events"] == names
