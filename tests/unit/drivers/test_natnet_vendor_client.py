"""A third-party NatNet client, unmodified, against our simulated Motive.

The client is the PyPI ``natnet`` package (0.3.0, TimSchneider42/python-natnet-client):
it connects to ``spotlab sim natnet``'s server, reads the model descriptions and
receives frames; what it decodes must equal the simulator's truth to float32
precision (NatNet sends float32 metres). Its behaviour judges our simulator
(docs/protocols/natnet.md §5 notes the one place the published protocol wins).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from spotlab.simulators.natnet import NatNetServer
from spotlab.simulators.natnet_scene import NatNetScene

natnet = pytest.importorskip("natnet")

RATE = 100.0


def _run_client(
    srv: NatNetServer, seconds: float, *, multicast: bool = False
) -> tuple[Any, list[Any], list[Any]]:
    frames: list[Any] = []
    descs: list[Any] = []
    client = natnet.NatNetClient(
        server_ip_address="127.0.0.1",
        local_ip_address="127.0.0.1",
        command_port=srv.port,
        data_port=srv.data_port,
        use_multicast=multicast,
    )
    client.on_data_frame_received_event.handlers.append(frames.append)
    client.on_data_description_received_event.handlers.append(descs.append)
    client.connect(timeout=3.0)
    version = client.protocol_version
    client.request_modeldef()
    client.run_async()
    try:
        time.sleep(seconds)
    finally:
        client.stop_async()
        client.shutdown()
    return version, descs, frames


def _check_frames(scene: NatNetScene, truth_path: Path, frames: list[Any], major: int) -> None:
    t = np.load(truth_path)
    row = {int(k): i for i, k in enumerate(t["frame"])}
    numbers = [f.prefix.frame_number for f in frames]
    assert len(frames) >= 0.5 * RATE
    assert numbers == list(range(numbers[0], numbers[0] + len(numbers))), "frames lost or reordered"
    for f in frames:
        i = row[f.prefix.frame_number]
        want = (t["markers_mm"][i] / 1000.0).astype(np.float32)
        (ms,) = f.marker_sets
        assert ms.model_name == "walker"
        np.testing.assert_array_equal(np.asarray(ms.marker_pos_list, dtype=np.float32), want)
        ids = [m.id_num for m in f.labeled_markers]
        assert ids == [1 << 16 | (k + 1) for k in range(scene.n_markers)]
        np.testing.assert_array_equal(
            np.asarray([m.pos for m in f.labeled_markers], dtype=np.float32), want
        )
        assert all(m.model_solved and m.has_model and not m.occluded for m in f.labeled_markers)
        assert all(m.residual == 0.0 for m in f.labeled_markers)
        (pose,) = scene.poses(t["markers_mm"][i])
        (rb,) = f.rigid_bodies
        assert rb.id_num == 1 and rb.tracking_valid
        np.testing.assert_array_equal(
            np.float32(rb.pos), np.asarray(pose.position_m, dtype=np.float32)
        )
        np.testing.assert_array_equal(
            np.float32(rb.rot), np.asarray(pose.quaternion, dtype=np.float32)
        )
        assert f.suffix.timestamp == t["time_s"][i] == f.prefix.frame_number / RATE
        assert f.suffix.stamp_camera_mid_exposure == round(t["time_s"][i] * 10_000_000)
        s = int(np.floor(t["time_s"][i] * 30 + 1e-9))
        assert f.suffix.timecode == ((s // 30) // 60) % 60 << 16 | (s // 30) % 60 << 8 | s % 30
        # NatNet 4.x: this client reads params from the precision timestamp (0 from us)
        assert f.suffix.param == 0
        assert f.skeletons == () and f.force_plates == () and f.devices == ()
        assert (f.assets == ()) if major >= 4 else (f.assets is None)


@pytest.mark.parametrize("version", [(3, 1), (4, 1)])
def test_vendor_client_decodes_what_the_simulator_served(
    tmp_path: Path, version: tuple[int, int]
) -> None:
    scene = NatNetScene(markers=40, cameras=6, rate_hz=RATE, seed=3)
    truth = tmp_path / "truth.npz"
    srv = NatNetServer(scene, version=version, truth=truth).start()
    try:
        got_version, descs, frames = _run_client(srv, 1.5)
    finally:
        srv.stop()
    assert got_version.components == (version[0], version[1], 0, 0)

    (desc,) = descs
    (ms,) = desc.marker_sets
    assert ms.name == "walker" and ms.marker_names == scene.labels
    (rb,) = desc.rigid_bodies
    assert rb.name == "pelvis" and rb.id_num == 1
    ref = scene.rigid_bodies()[0]
    np.testing.assert_array_equal(
        np.asarray([m.pos for m in rb.markers], dtype=np.float32), ref.offsets_m.astype(np.float32)
    )
    names = tuple(m.name for m in rb.markers)
    assert names == (("LASI", "RASI", "LPSI", "RPSI") if version[0] >= 4 else (None,) * 4)
    assert [c.name for c in desc.cameras] == [f"cam{k}" for k in range(1, 7)]
    _check_frames(scene, truth, frames, version[0])


def test_vendor_client_receives_multicast_on_loopback(tmp_path: Path) -> None:
    scene = NatNetScene(markers=40, cameras=2, rate_hz=RATE, seed=0)
    truth = tmp_path / "truth.npz"
    try:
        srv = NatNetServer(scene, truth=truth, multicast=True).start()
    except OSError as exc:
        pytest.skip(f"no free command/data port pair on loopback: {exc}")
    try:
        try:
            _, descs, frames = _run_client(srv, 1.0, multicast=True)
        except Exception as exc:  # the client's own error types for a refused membership
            pytest.skip(f"this host does not route multicast on loopback: {exc!r}")
    finally:
        srv.stop()
    if not frames:
        pytest.skip("this host does not deliver multicast on loopback")
    assert descs and descs[0].marker_sets[0].marker_names == scene.labels
    _check_frames(scene, truth, frames, 4)
