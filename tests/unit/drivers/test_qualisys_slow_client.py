"""A QTM client too slow for the stream: the server skips its frames, the client counts them.

A raw client with a small receive buffer asks for every frame (3D and 2D, at 1000 Hz)
and stops reading for a while: once the bytes waiting for it pass the simulator's limit,
the server skips its frames (QTM says nothing about it). Read again, the stream must
show each skipped frame as a frame number that skips, counted in ``lost_frames``, and
hold every frame the server sent, once, in order.
"""

from __future__ import annotations

import select
import socket
import time

import numpy as np

from spotlab.drivers.qualisys.decoder import QualisysDecoder
from spotlab.drivers.qualisys.protocol import command_packet
from spotlab.simulators.qualisys import QualisysServer, QualisysSimOptions

STALL_S = 1.5


def _read_for(sock: socket.socket, seconds: float) -> bytes:
    out = bytearray()
    deadline = time.monotonic() + seconds
    while (left := deadline - time.monotonic()) > 0:
        if select.select([sock], [], [], left)[0]:
            chunk = sock.recv(1 << 20)
            if not chunk:
                break
            out += chunk
    return bytes(out)


def test_a_stalled_client_gets_frames_skipped_and_counts_them() -> None:
    options = QualisysSimOptions(cameras=8, markers=40, rate_hz=1000.0, seed=1)
    with QualisysServer(options) as srv:
        sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        sock.connect(("127.0.0.1", srv.port))
        try:
            sock.sendall(command_packet("StreamFrames AllFrames 3D 2D"))
            data = _read_for(sock, 0.2)
            time.sleep(STALL_S)  # busy: QTM goes on serving
            data += _read_for(sock, 1.0)
            sock.sendall(command_packet("StreamFrames Stop"))
            data += _read_for(sock, 0.3)
        finally:
            sock.close()
    truth = srv.truth()
    dec = QualisysDecoder(40)
    block = dec.feed(data, 0)
    skipped = truth["skipped"]
    assert len(skipped) > 0, "the stalled client's socket never filled"
    assert np.array_equal(block.seq, truth["frame"]), "every frame served, once, in order"
    assert dec.stats.lost_frames == len(skipped)
    assert 1 <= dec.stats.gaps <= len(skipped)
