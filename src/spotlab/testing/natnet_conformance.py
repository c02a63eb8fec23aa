"""Conformance suite of the NatNet driver: the simulated Motive in CI, a real one on a bench.

``pytest tests/conformance/test_natnet.py --hw natnet=HOST[:PORT]`` runs it against a
real Motive (streaming on, unicast or multicast, at least one marker set with
labelled markers and a rigid body defined, markers in view). Subclass
:class:`NatNetConformance` and provide a ``natnet_address`` fixture that yields the
server's ``HOST:PORT``. Every assertion is one a real Motive satisfies too: the
NatNet version is 3.x or 4.x, descriptions are well formed, frames are numbered
one by one and stamped on a clock that advances, the server keeps a client that
sends ``NAT_KEEPALIVE`` and takes one back that connects again. Nothing compares
with a simulator's truth.
"""

from __future__ import annotations

import socket
import time

import numpy as np

from spotlab.drivers.natnet import NatNetDriver
from spotlab.drivers.natnet.wire import (
    NAT_DISCONNECT,
    NAT_MODELDEF,
    NAT_REQUEST_MODELDEF,
    NAT_SERVERINFO,
    connect_request,
    parse_model_definitions,
    parse_server_info,
    request,
    split_packet,
)
from spotlab.testing.streaming import collect

#: Seconds of frames the streaming tests collect.
SECONDS = 3.0


def ask_raw(
    address: tuple[str, int], asks: list[tuple[bytes, int]], timeout: float = 3.0
) -> list[bytes]:
    """Send each ``(packet, answer)`` in turn from one fresh socket, as a client does, and
    return the payload of each answer (then ``NAT_DISCONNECT``, so that the server does
    not stream to that socket)."""
    out: list[bytes] = []
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.settimeout(0.5)
        try:
            for packet, answer in asks:
                out.append(_ask_one(sock, address, packet, answer, timeout))
        finally:
            sock.sendto(request(NAT_DISCONNECT), address)
    return out


def _ask_one(
    sock: socket.socket, address: tuple[str, int], packet: bytes, answer: int, timeout: float
) -> bytes:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        sock.sendto(packet, address)
        try:
            while True:
                message_id, payload = split_packet(sock.recv(65536))
                if message_id == answer:
                    return payload
        except TimeoutError:
            continue
    raise AssertionError(f"no message {answer} from {address} within {timeout} s")


class NatNetConformance:
    """Tests every NatNet server must pass. Needs a ``natnet_address`` fixture."""

    #: Seconds a client streams in the keep-alive test: longer than the server keeps a
    #: client that sends nothing (Motive: 10 s and more).
    keepalive_span_s: float = 12.0

    def test_server_info_names_a_natnet_3_or_4_server_with_a_clock(
        self, natnet_address: str
    ) -> None:
        driver = NatNetDriver(natnet_address)
        (payload,) = ask_raw(driver.address, [(connect_request(), NAT_SERVERINFO)])
        info = parse_server_info(payload)
        assert info.name, "the server info names no application"
        assert info.version[0] in (3, 4), info
        assert info.app_version[0] >= 1, info
        assert info.clock_hz >= 1_000_000, "NatNet >= 3 announces a high-resolution clock"
        if info.multicast:
            assert 224 <= int(info.group.split(".")[0]) <= 239, info.group
        assert 0 < info.data_port <= 65535 or not info.multicast, info

    def test_model_descriptions_hold_a_labelled_marker_set_and_rigid_bodies(
        self, natnet_address: str
    ) -> None:
        driver = NatNetDriver(natnet_address)
        raw_info, payload = ask_raw(
            driver.address,
            [(connect_request(), NAT_SERVERINFO), (request(NAT_REQUEST_MODELDEF), NAT_MODELDEF)],
        )
        models = parse_model_definitions(payload, parse_server_info(raw_info).version)
        sets = {k: v for k, v in models.marker_sets.items() if k.lower() != "all"}
        assert sets, f"no marker set but Motive's 'all': {sorted(models.marker_sets)}"
        for name, labels in sets.items():
            assert labels, f"marker set {name!r} names no marker"
            assert len(set(labels)) == len(labels), f"marker set {name!r} repeats a label"
            assert all(label.strip() for label in labels), name
        assert models.rigid_bodies, "no rigid body described"
        ids = list(models.rigid_bodies.values())
        assert len(set(ids)) == len(ids), f"rigid body ids repeat: {models.rigid_bodies}"

    def test_frames_are_contiguous_and_stamped_on_an_advancing_clock(
        self, natnet_address: str
    ) -> None:
        with NatNetDriver(natnet_address) as driver:
            spec = driver.spec
            block = collect(driver, SECONDS)
            rate = driver.rate_hz
            last = driver.last_frame
            described = set(driver.models.rigid_bodies.values()) if driver.models else set()
        assert spec.kind == "point3d" and spec.n_markers == len(driver.labels) > 0
        assert block.data.shape[1:] == (spec.n_markers, 1, 3)
        assert 1.0 <= rate <= 2000.0
        assert len(block) >= 0.8 * SECONDS * rate, f"{len(block)} frames in {SECONDS} s"
        assert np.all(np.diff(block.seq) == 1), "frame numbers skip or repeat"
        assert np.all(np.diff(block.ticks) > 0), "frame stamps do not advance"
        period = float(np.median(np.diff(block.ticks))) / spec.tick_hz
        np.testing.assert_allclose(period, 1.0 / rate, rtol=0.02)
        assert driver.stats.crc_errors == 0
        assert np.isfinite(block.data).any(), "no marker of the set was seen"
        assert last is not None and last.frame_number == block.seq[-1]
        assert set(last.rigid_bodies) <= described, "a frame holds an undescribed rigid body"
        for pose in last.rigid_bodies.values():
            q = pose[3:7]
            if np.all(np.isfinite(q)) and np.any(q != 0):
                np.testing.assert_allclose(np.linalg.norm(q), 1.0, atol=1e-3)

    def test_a_client_that_sends_keepalives_keeps_streaming(self, natnet_address: str) -> None:
        with NatNetDriver(natnet_address) as driver:
            collect(driver, 0.5)
            block = collect(driver, self.keepalive_span_s)
            tail = collect(driver, 1.0)
        assert np.all(np.diff(block.seq) == 1)
        assert len(tail) > 0, "the server stopped sending to a client that kept alive"
        assert driver.stats.reconnects == 0

    def test_a_client_that_reconnects_streams_again(self, natnet_address: str) -> None:
        driver = NatNetDriver(natnet_address)
        try:
            driver.start()
            first = collect(driver, 1.0)
            driver.stop()
            driver.close()  # NAT_DISCONNECT
            driver.start()
            again = collect(driver, 1.0)
        finally:
            driver.close()
        assert again.seq[0] > first.seq[-1], "frame numbers went back after a reconnect"
        assert again.ticks[0] > first.ticks[-1], "the clock went back after a reconnect"
        assert np.all(np.diff(again.seq) == 1)

    def test_two_clients_receive_the_same_frames(self, natnet_address: str) -> None:
        with NatNetDriver(natnet_address) as a, NatNetDriver(natnet_address) as b:
            x = collect(a, 1.5)
            y = collect(b, 1.5)
        common, ia, ib = np.intersect1d(x.seq, y.seq, return_indices=True)
        assert len(common) > 0, "the two clients got no frame in common"
        np.testing.assert_array_equal(x.ticks[ia], y.ticks[ib])
        np.testing.assert_array_equal(x.data[ia], y.data[ib])
