"""Qualisys' own client, the unmodified ``qtm-rt`` package, against our QTM simulator.

The client is the judge of the simulator: it connects (negotiating version 1.25),
reads the parameters, streams 3D, 6D, 3DNoLabels and 2D, follows the state
events and the control flow; what it decodes must equal the simulator's truth to
float32 precision.
"""

from __future__ import annotations

import asyncio
import xml.etree.ElementTree as ET
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

from spotlab.simulators.qualisys import QualisysServer, QualisysSimOptions

qtm_rt = pytest.importorskip("qtm_rt")


@pytest.fixture
def server() -> Iterator[QualisysServer]:
    options = QualisysSimOptions(markers=40, cameras=6, rate_hz=100.0, seed=3, password="pw")
    with QualisysServer(options) as s:
        yield s


def run(coro: Any) -> Any:
    return asyncio.run(coro)


def test_vendor_client_streams_what_the_truth_holds(server: QualisysServer) -> None:
    packets: list[Any] = []

    async def session() -> bytes:
        conn = await qtm_rt.connect("127.0.0.1", port=server.port, version="1.25")
        assert conn is not None
        xml = await conn.get_parameters(parameters=["all"])
        await conn.stream_frames(components=["3d", "6d"], on_packet=packets.append)
        await asyncio.sleep(1.0)
        await conn.stream_frames_stop()
        await asyncio.sleep(0.05)
        conn.disconnect()
        return bytes(xml)

    xml = run(session())
    server.stop()
    truth = server.truth()
    root = ET.fromstring(xml)
    assert [e.text for e in root.findall("*/Label/Name")] == truth["labels"].tolist()
    assert [e.text for e in root.findall("*/Body/Name")] == truth["body_names"].tolist()
    assert float(root.findtext("General/Frequency") or 0) == 100.0
    assert 60 <= len(packets) <= 140
    frames = [p.framenumber for p in packets]
    assert frames == list(range(frames[0], frames[0] + len(frames)))
    row = {int(n): i for i, n in enumerate(truth["frame"])}
    for p in packets:
        i = row[p.framenumber]
        assert p.timestamp == truth["timestamp_us"][i] == round((p.framenumber - 1) * 1e4)
        head, markers = p.get_3d_markers()
        assert head.marker_count == 40
        got = np.array([[m.x, m.y, m.z] for m in markers])
        assert np.array_equal(got, truth["markers_mm"][i].astype(np.float32).astype(np.float64))
        head6, bodies = p.get_6d()
        assert head6.body_count == 3
        pos = np.array([[b[0].x, b[0].y, b[0].z] for b in bodies])
        rot = np.array([b[1].matrix for b in bodies]).reshape(3, 3, 3).transpose(0, 2, 1)
        assert np.array_equal(pos, truth["body_positions_mm"][i].astype(np.float32))
        assert np.abs(rot - truth["body_rotations"][i]).max() < 1e-6


def test_vendor_client_no_labels_2d_and_current_frame(server: QualisysServer) -> None:
    async def session() -> tuple[Any, Any]:
        conn = await qtm_rt.connect("127.0.0.1", port=server.port)
        one = await conn.get_current_frame(components=["3dnolabels", "2d"])
        got: list[Any] = []
        await conn.stream_frames(
            frames="frequency:50", components=["3dnolabels", "2d"], on_packet=got.append
        )
        await asyncio.sleep(0.3)
        await conn.stream_frames_stop()
        conn.disconnect()
        return one, got

    one, got = run(session())
    server.stop()
    truth = server.truth()
    assert one.framenumber >= 1
    assert np.all(np.diff([p.framenumber for p in got]) == 2)
    row = {int(n): i for i, n in enumerate(truth["frame"])}
    for p in got:
        _, markers = p.get_3d_markers_no_label()
        ids = np.array([m.id for m in markers])
        xyz = np.array([[m.x, m.y, m.z] for m in markers])
        true = truth["markers_mm"][row[p.framenumber]].astype(np.float32)
        assert np.array_equal(xyz, true[ids - 1])
        head, cams = p.get_2d_markers()
        assert head.camera_count == 6 and len(cams) == 6
        assert sum(len(c) for c in cams) > 40  # every marker is seen by several cameras
        assert all(0 <= m.x < 1280 * 64 and 0 <= m.y < 1024 * 64 for c in cams for m in c)


def test_vendor_client_state_events_and_control(server: QualisysServer) -> None:
    events: list[Any] = []

    async def session() -> list[Any]:
        conn = await qtm_rt.connect("127.0.0.1", port=server.port, on_event=events.append)
        out = [await conn.get_state(), await conn.qtm_version(), await conn.byte_order()]
        with pytest.raises(qtm_rt.QRTCommandException):
            await conn.take_control("wrong")
        with pytest.raises(qtm_rt.QRTCommandException):
            await conn.start()  # not master
        out.append(await conn.take_control("pw"))
        out.append(await conn.start())
        out.append(await conn.await_event(qtm_rt.QRTEvent.EventCaptureStarted, timeout=2))
        out.append(await conn.stop())
        out.append(await conn.await_event(timeout=2))
        out.append(await conn.get_state())
        out.append(await conn.release_control())
        conn.disconnect()
        return out

    out = run(session())
    assert out[0] == qtm_rt.QRTEvent.EventConnected
    assert out[1].startswith(b"QTM Version is") and out[2] == b"Byte order is little endian"
    assert out[3] == b"You are now master" and out[4] == b"Starting measurement"
    assert out[5] == qtm_rt.QRTEvent.EventCaptureStarted
    assert out[6] == b"Stopping measurement"
    assert out[7] == out[8] == qtm_rt.QRTEvent.EventCaptureStopped
    assert out[9] == b"You are now a regular client"
    assert qtm_rt.QRTEvent.EventCaptureStarted in events


def test_vendor_client_refused_version_and_disconnect() -> None:
    options = QualisysSimOptions(markers=4, rate_hz=200.0, faults="disconnect@0.2:0.1")
    lost: list[Any] = []
    with QualisysServer(options) as server:

        async def session() -> tuple[Any, int]:
            refused = await qtm_rt.connect("127.0.0.1", port=server.port, version="1.99")
            conn = await qtm_rt.connect("127.0.0.1", port=server.port, on_disconnect=lost.append)
            got: list[Any] = []
            await conn.stream_frames(components=["3d"], on_packet=got.append)
            for _ in range(100):
                if lost:
                    break
                await asyncio.sleep(0.02)
            await asyncio.sleep(0.15)
            again = await qtm_rt.connect("127.0.0.1", port=server.port)
            state = await again.get_state()
            again.disconnect()
            return refused, len(got), state

        refused, n, state = run(session())
    assert refused is None  # the client's way of saying the version was refused
    assert lost and 20 <= n <= 80
    assert state == qtm_rt.QRTEvent.EventConnected
