"""A NatNet client too slow for the stream loses datagrams in its own socket buffer.

NatNet is UDP: nothing tells the client. The driver stops reading for a while with a
receive buffer too small to hold what the server sends meanwhile (a real, not emulated,
overflow); the frames it then reads must show the loss as frame numbers that skip,
counted in ``lost_frames`` and ``gaps``, and every frame it did read must be one the
server sent, once.
"""

from __future__ import annotations

import socket
import time
from pathlib import Path

import numpy as np

from spotlab.core.frames import FrameBlock
from spotlab.drivers.natnet import NatNetDriver
from spotlab.simulators.natnet import NatNetServer
from spotlab.simulators.natnet_scene import NatNetScene

STALL_S = 0.4


def test_a_stalled_client_counts_the_datagrams_its_full_buffer_lost(tmp_path: Path) -> None:
    scene = NatNetScene(markers=40, cameras=2, rate_hz=200.0, seed=1)
    truth = tmp_path / "truth.npz"
    blocks: list[FrameBlock] = []
    with NatNetServer(scene, truth=truth) as srv:
        drv = NatNetDriver(srv.address)
        with drv:
            sock = drv._sock  # the test shrinks the buffer a busy host would fill
            assert sock is not None
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
            for _ in range(20):
                block = drv.recv(0.5)
                if block is not None:
                    blocks.append(block)
            time.sleep(STALL_S)  # the client is busy: the server goes on sending
            deadline = time.monotonic() + 0.5
            while time.monotonic() < deadline:
                block = drv.recv(0.1)
                if block is not None:
                    blocks.append(block)
            stats = drv.stats
    got = FrameBlock.concat([b for b in blocks if len(b)])
    sent = np.load(truth)["frame"]
    assert set(got.seq.tolist()) <= set(sent.tolist())
    assert np.all(np.diff(got.seq) > 0), "each frame once, in order"
    missing = int(np.count_nonzero((sent > got.seq[0]) & (sent < got.seq[-1]))) - (len(got) - 2)
    assert missing >= 0.5 * STALL_S * scene.rate_hz, missing  # most of the stall was lost
    assert stats.lost_frames == missing
    assert stats.gaps >= 1 and stats.reconnects == 0
