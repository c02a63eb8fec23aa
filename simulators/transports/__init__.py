"""Transports that carry simulated devices: sim:// URLs, pseudo-terminals, TCP.

``protocol_sim`` is found by pyserial's ``serial_for_url`` through
``serial.protocol_handler_packages``; ``pty.PtyServer`` and ``tcp.TcpServer``
serve a device to a separate host process.
"""
