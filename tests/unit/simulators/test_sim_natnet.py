"""The simulated NatNet server against docs/protocols/natnet.md: golden vectors, serving, truth."""

from __future__ import annotations

import socket
import struct
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from spotlab.simulators import natnet_wire as nw
from spotlab.simulators.natnet import NatNetServer, parse_faults
from spotlab.simulators.natnet_scene import NatNetScene
from spotlab.testing.golden import golden_vector

# docs/protocols/natnet.md §6
SPEC = Path(__file__).parents[3] / "docs" / "protocols" / "natnet.md"
GOLDEN_SERVER_INFO = golden_vector(SPEC, "Server info")
GOLDEN_FRAME_41 = golden_vector(SPEC, "A frame with 2 labelled markers")
GOLDEN_FRAME_31 = golden_vector(SPEC, "The same frame in NatNet 3.1")


def golden_content() -> nw.FrameContent:
    return nw.FrameContent(
        frame_number=1234,
        marker_set="walker",
        markers_m=np.array([[0.25, -0.5, 1.125], [-0.75, 1.5, 0.0625]]),
        labelled_ids=[0x00010001, 0x00010002],
        timecode=0x01020304,
        timecode_sub=0,
        timestamp_s=10.25,
        stamps=(102_500_000, 102_520_000, 102_530_000),
        marker_size_m=0.015625,
    )


def test_server_info_is_the_golden_vector() -> None:
    assert len(GOLDEN_SERVER_INFO) == 283
    assert nw.server_info((4, 1), clock_hz=10_000_000, data_port=1511) == GOLDEN_SERVER_INFO


@pytest.mark.parametrize(
    ("version", "golden"), [((4, 1), GOLDEN_FRAME_41), ((3, 1), GOLDEN_FRAME_31)]
)
def test_frame_with_two_labelled_markers_is_the_golden_vector(
    version: nw.Version, golden: bytes
) -> None:
    assert nw.frame_of_data(version, golden_content()) == golden


def test_timecode_packs_hours_minutes_seconds_frames() -> None:
    assert nw.timecode(3723 + 4 / 30 + 0.001) == (0x01020304, 0)


def test_faults_parse_and_refuse() -> None:
    f = parse_faults("drop@1.5:3, disconnect@4")
    assert [(x.kind, x.at_s, x.n) for x in f] == [("drop", 1.5, 3), ("disconnect", 4.0, 1)]
    assert f[1].duration_s == float("inf")
    with pytest.raises(ValueError, match="expected drop"):
        parse_faults("explode@1")


def test_scene_pelvis_pose_reproduces_its_markers() -> None:
    scene = NatNetScene(markers=40, cameras=4, rate_hz=100.0, seed=0)
    x = scene.markers_mm(np.array([1.37]))[0]
    (pose,) = scene.poses(x)
    (rb,) = scene.rigid_bodies()
    qx, qy, qz, qw = pose.quaternion
    r = np.array(
        [
            [1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qz * qw), 2 * (qx * qz + qy * qw)],
            [2 * (qx * qy + qz * qw), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qx * qw)],
            [2 * (qx * qz - qy * qw), 2 * (qy * qz + qx * qw), 1 - 2 * (qx * qx + qy * qy)],
        ]
    )
    fitted = np.asarray(pose.position_m) + rb.offsets_m @ r.T
    pelvis = x[scene.pelvis] / 1000.0
    assert np.abs(fitted - pelvis).max() < 0.02  # soft tissue moves a few mm at most
    assert pose.mean_error_m < 0.01


def _request(sock: socket.socket, port: int, message_id: int, payload: bytes = b"") -> None:
    sock.sendto(struct.pack("<HH", message_id, len(payload)) + payload, ("127.0.0.1", port))


def test_server_answers_connect_and_streams_unicast_with_truth(tmp_path: Path) -> None:
    truth = tmp_path / "truth.npz"
    scene = NatNetScene(markers=6, cameras=2, rate_hz=200.0, seed=1)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind(("127.0.0.1", 0))
        sock.settimeout(2.0)
        with NatNetServer(scene, version=(3, 1), truth=truth, faults="drop@0.1:2") as srv:
            _request(sock, srv.port, nw.NAT_CONNECT, b"Ping\0")
            info, _ = sock.recvfrom(65536)
            assert info[:4] == b"\x01\x00\x17\x01" and info[264:266] == b"\x03\x01"
            _request(sock, srv.port, nw.NAT_REQUEST_MODELDEF)
            frames = []
            deadline = time.monotonic() + 0.5
            while time.monotonic() < deadline:
                data, _ = sock.recvfrom(65536)
                if data[:2] == b"\x07\x00":
                    frames.append(struct.unpack_from("<i", data, 4)[0])
            _request(sock, srv.port, nw.NAT_DISCONNECT)
            time.sleep(0.05)
    t = np.load(truth)
    assert t["markers_mm"].shape == (len(t["frame"]), 6, 3)
    assert list(t["labels"]) == ["HEAD", "C7", "LSHO", "RSHO", "LELB", "RELB"]
    assert len(t["dropped"]) == 2 and not set(t["dropped"]) & set(t["frame"])
    assert set(frames) <= set(t["frame"])
    np.testing.assert_allclose(t["time_s"], t["frame"] / 200.0)
    served = set(t["frame"]) | set(t["dropped"])
    assert sorted(served) == list(range(min(served), max(served) + 1))


def test_cli_prints_the_address_first(tmp_path: Path) -> None:
    with subprocess.Popen(
        [sys.executable, "-m", "spotlab.console.cli", "sim", "natnet", "--seconds", "3",
         "--markers", "4", "--truth", str(tmp_path / "t.npz")],
        stdout=subprocess.PIPE, text=True,
    ) as proc:  # fmt: skip
        assert proc.stdout is not None
        host, _, port = proc.stdout.readline().strip().partition(":")
        proc.terminate()
        proc.wait(10)
    assert host == "127.0.0.1" and int(port) > 0
    assert (tmp_path / "t.npz").is_file()
