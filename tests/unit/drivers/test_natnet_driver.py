"""``spotlab record --device natnet=HOST:PORT`` against the simulated Motive.

The recording keeps every frame the server sent (frame numbers contiguous), and
its markers equal the simulator's truth and what a third-party client (PyPI
``natnet``) decodes from the same server at the same time.
"""

from __future__ import annotations

import json
import socket
import struct
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from spotlab.acquisition.replay import replay
from spotlab.console.cli import main
from spotlab.drivers.natnet import NatNetDriver
from spotlab.io import TRIAL_READERS
from spotlab.processing.decoding import decoder_for
from spotlab.simulators.natnet import NatNetServer
from spotlab.simulators.natnet_scene import NatNetScene


def _recorded(path: Path) -> tuple[np.ndarray, np.ndarray]:
    blocks = [b for _, b in replay(path, decoder_for)]
    seq = np.concatenate([b.seq for b in blocks])
    data = np.concatenate([b.data for b in blocks])
    return seq, data


def _as_served(truth_mm: np.ndarray) -> np.ndarray:
    """Truth (mm) as NatNet carries it: float32 metres, back in mm."""
    return (truth_mm / 1000.0).astype(np.float32).astype(np.float64) * 1000.0


def test_record_5_s_keeps_every_frame_and_matches_truth_and_vendor_client(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    natnet = pytest.importorskip("natnet")
    scene = NatNetScene(markers=40, cameras=8, rate_hz=100.0, seed=2)
    truth = tmp_path / "truth.npz"
    out = tmp_path / "rec.spj"
    vendor: list[Any] = []
    with NatNetServer(scene, truth=truth) as srv:
        client = natnet.NatNetClient(
            server_ip_address="127.0.0.1",
            local_ip_address="127.0.0.1",
            command_port=srv.port,
            use_multicast=False,
        )
        client.on_data_frame_received_event.handlers.append(vendor.append)
        client.connect(timeout=3.0)
        client.run_async()
        try:
            code = main(
                ["record", "--device", f"natnet={srv.address}", "--seconds", "5", "--out", str(out)]
            )
        finally:
            client.stop_async()
            client.shutdown()
    assert code == 0, capsys.readouterr().err
    assert "natnet:" in capsys.readouterr().out

    assert main(["info", str(out), "--json"]) == 0
    (stream,) = json.loads(capsys.readouterr().out)["streams"]
    assert stream["frames"] == stream["live_stats"]["frames"], "the journal lost start-up frames"
    assert stream["lost_frames"] == stream["crc_errors"] == stream["duplicates"] == 0

    seq, data = _recorded(out)
    assert len(seq) == stream["frames"] >= 450
    assert list(seq) == list(range(seq[0], seq[0] + len(seq))), "a frame was lost"
    t = np.load(truth)
    row = {int(k): i for i, k in enumerate(t["frame"])}
    want = _as_served(t["markers_mm"][[row[int(k)] for k in seq]])
    np.testing.assert_array_equal(data[:, :, 0, :], want)

    by_number = {f.prefix.frame_number: f for f in vendor}
    common = [i for i, k in enumerate(seq) if int(k) in by_number]
    assert len(common) >= 0.9 * len(seq)
    theirs = np.asarray(
        [by_number[int(seq[i])].marker_sets[0].marker_pos_list for i in common], dtype=np.float32
    )
    np.testing.assert_array_equal(data[common, :, 0, :], theirs.astype(np.float64) * 1000.0)


def test_driver_reads_natnet_3_labels_rate_and_clock() -> None:
    scene = NatNetScene(markers=8, cameras=2, rate_hz=120.0, seed=0)
    with NatNetServer(scene, version=(3, 1)) as srv:
        drv = NatNetDriver(srv.address)
        with drv:
            blocks = [drv.recv(1.0) for _ in range(5)]
            meta = drv.metadata()
            assert len(srv.clients) == 1
        time.sleep(0.2)
        assert srv.clients == {}, "NAT_DISCONNECT at close"
    assert drv.spec.kind == "point3d" and drv.spec.n_markers == 8
    assert drv.spec.rate_hz == 120.0 and drv.spec.tick_hz == 10_000_000
    assert drv.spec.metadata["marker_labels"] == list(scene.labels)
    assert meta["natnet_version"] == [3, 1] and meta["rigid_bodies"] == {}
    assert all(b is not None and len(b) for b in blocks)


def _fake_server(version: bytes, stop: threading.Event) -> tuple[socket.socket, threading.Thread]:
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.settimeout(0.05)

    def serve() -> None:
        while not stop.is_set():
            try:
                _, addr = sock.recvfrom(4096)
            except TimeoutError:
                continue
            if version.startswith(b"RAW:"):
                sock.sendto(version[4:], addr)
                continue
            body = b"old-motive".ljust(256, b"\0") + bytes((2, 0, 0, 0)) + version
            sock.sendto(struct.pack("<HH", 1, len(body)) + body, addr)

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    return sock, thread


@pytest.mark.parametrize(
    ("reply", "message"),
    [
        (bytes((2, 9, 0, 0)), "speaks NatNet 2.9"),
        (bytes((5, 0, 0, 0)), "speaks NatNet 5.0"),
        (b"RAW:HTTP/1.1 400 Bad Request\r\n", "not a NatNet server"),
        (b"RAW:\x01\x00\x05\x00short", "bad NatNet server info: server info holds 264"),
    ],
)
def test_record_refuses_another_natnet_version_or_a_malformed_reply(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], reply: bytes, message: str
) -> None:
    stop = threading.Event()
    sock, thread = _fake_server(reply, stop)
    try:
        port = sock.getsockname()[1]
        out = tmp_path / "rec.spj"
        code = main(["record", "--device", f"natnet=127.0.0.1:{port}", "--seconds", "1",
                     "--out", str(out)])  # fmt: skip
    finally:
        stop.set()
        thread.join(2)
        sock.close()
    err = capsys.readouterr().err.strip().splitlines()
    assert code != 0 and len(err) == 1
    assert err[0].startswith("spotlab: error:") and message in err[0]
    assert not out.exists()


def test_record_names_a_silent_address(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind(("127.0.0.1", 0))  # bound, never answers
        port = sock.getsockname()[1]
        t0 = time.monotonic()
        code = main(["record", "--device", f"natnet=127.0.0.1:{port}", "--seconds", "1",
                     "--out", str(tmp_path / "r.spj")])  # fmt: skip
    err = capsys.readouterr().err.strip().splitlines()
    assert code != 0 and len(err) == 1 and err[0].startswith("spotlab: error:")
    assert "no server info" in err[0] and time.monotonic() - t0 < 10


def test_export_c3d_of_a_natnet_recording_gives_the_labelled_markers(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    scene = NatNetScene(markers=10, cameras=4, rate_hz=100.0, seed=1)
    out, c3d = tmp_path / "rec.spj", tmp_path / "rec.c3d"
    with NatNetServer(scene, faults="drop@0.5:3") as srv:
        code = main(["record", "--device", f"natnet={srv.address}", "--seconds", "1.5",
                     "--out", str(out)])  # fmt: skip
    assert code == 0, capsys.readouterr().err
    seq, data = _recorded(out)
    capsys.readouterr()
    assert main(["info", str(out)]) == 0
    assert f"10 labelled 3-D markers: {' '.join(scene.labels)}" in capsys.readouterr().out
    assert main(["export", str(out), "--c3d", str(c3d)]) == 0
    assert "converted" in capsys.readouterr().out
    trial = TRIAL_READERS[".c3d"](c3d)
    assert trial.labels == list(scene.labels) and trial.point_rate == 100.0
    assert trial.n_frames == seq[-1] - seq[0] + 1 == len(seq) + 3  # the dropped frames: NaN
    rows = seq - seq[0]
    np.testing.assert_allclose(trial.points[rows], data[:, :, 0, :], atol=1e-3)
    missing = np.setdiff1d(np.arange(trial.n_frames), rows)
    assert len(missing) == 3 and np.isnan(trial.points[missing]).all()


def test_a_server_that_falls_silent_and_returns_is_recorded_across_the_outage(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    scene = NatNetScene(markers=6, cameras=2, rate_hz=100.0, seed=0)
    out, truth = tmp_path / "rec.spj", tmp_path / "truth.npz"
    with NatNetServer(scene, truth=truth, faults="disconnect@0.5:3") as srv:
        code = main(["record", "--device", f"natnet={srv.address}", "--seconds", "5",
                     "--out", str(out), "--json"])  # fmt: skip
    assert code == 0, capsys.readouterr().err
    result = json.loads(capsys.readouterr().out)
    (stream,) = result["streams"]
    assert stream["reconnects"] == 1 and stream["gaps"] == 1 and stream["lost_frames"] == 0
    assert result["away_at_end"] == {}
    seq, data = _recorded(out)
    t = np.load(truth)
    served = t["frame"][(t["frame"] >= seq[0]) & (t["frame"] <= seq[-1])]
    assert list(seq) == list(served), "a frame the server sent is missing"
    assert np.diff(seq).max() >= 250  # the outage: 3 s without frames
    row = {int(k): i for i, k in enumerate(t["frame"])}
    want = _as_served(t["markers_mm"][[row[int(k)] for k in seq]])
    np.testing.assert_array_equal(data[:, :, 0, :], want)


def test_record_names_the_marker_sets_when_the_one_asked_for_is_missing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    scene = NatNetScene(markers=4, cameras=2, rate_hz=100.0)
    with NatNetServer(scene) as srv:
        code = main(["record", "--device", f"natnet={srv.address},marker_set=nope",
                     "--seconds", "1", "--out", str(tmp_path / "r.spj")])  # fmt: skip
    err = capsys.readouterr().err.strip().splitlines()
    assert code != 0 and len(err) == 1
    assert "no marker set 'nope'; the server has ['walker']" in err[0]
