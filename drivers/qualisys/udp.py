"""QTM's UDP stream option: the socket Data packets arrive on, one packet a datagram.

``StreamFrames AllFrames UDP:PORT 3D 6D`` asks QTM to send each Data packet as one
UDP datagram to ``PORT`` at the address the command came from (``UDP:ADDR:PORT``
names another address); commands, replies and events stay on the TCP connection
(docs/protocols/qualisys.md §5). Datagrams arrive whole or not at all, so the
driver feeds them to the same decoder as the TCP stream; a datagram the network
drops is a gap in QTM's frame numbers, counted as a lost frame.
"""

from __future__ import annotations

import errno
import select
import socket
import time

#: Receive buffer asked of the kernel: about 2 s of 40 labelled markers at 300 Hz.
RCVBUF = 4 << 20
#: A datagram larger than this is not a QTM packet of ours (65 507 is UDP's own limit).
MAX_DATAGRAM = 65_535


class UdpReceiver:
    """A UDP socket bound where QTM is told to send its Data packets.

    Parameters
    ----------
    local_host : str
        The local address of the TCP connection to QTM: QTM sends to the address
        the command came from.
    port : int
        UDP port to bind, 0 for one the system picks (:attr:`port` tells which).
    server_host : str
        QTM's address: datagrams from any other sender are counted in
        :attr:`foreign` and dropped.

    Raises
    ------
    OSError
        If the port cannot be bound (in use, no permission).
    """

    def __init__(self, local_host: str, port: int, server_host: str) -> None:
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RCVBUF)
            sock.bind((local_host, port))
        except OSError:
            sock.close()
            raise
        sock.setblocking(False)
        self.sock = sock
        self.port = int(sock.getsockname()[1])
        self.server_ip = socket.gethostbyname(server_host)
        self.datagrams = 0
        self.foreign = 0

    def fileno(self) -> int:
        """The socket's descriptor (for ``select``)."""
        return self.sock.fileno()

    def read_available(self, limit: int = 256) -> bytes:
        """Every datagram waiting now (at most ``limit``), from QTM only, joined.

        Returns
        -------
        bytes
            Whole packets one after another; empty when none is waiting.
        """
        out = bytearray()
        for _ in range(limit):
            try:
                data, (host, _) = self.sock.recvfrom(MAX_DATAGRAM)
            except BlockingIOError:
                break
            except OSError as exc:
                if exc.errno in (errno.ECONNREFUSED, errno.EINTR):
                    continue
                raise
            if host != self.server_ip:
                self.foreign += 1
                continue
            self.datagrams += 1
            out += data
        return bytes(out)

    def drain(self, quiet_s: float = 0.05, limit_s: float = 0.5) -> bytes:
        """Datagrams still on their way after the stream was stopped: read until none has
        come for ``quiet_s`` seconds, or ``limit_s`` seconds in all."""
        out = bytearray()
        end = time.monotonic() + limit_s
        while True:
            left = min(quiet_s, end - time.monotonic())
            if left <= 0 or not select.select([self.sock], [], [], left)[0]:
                return bytes(out)
            out += self.read_available()

    def close(self) -> None:
        """Close the socket."""
        self.sock.close()
