"""Transports that carry simulated devices: sim:// URLs, pseudo-terminals, TCP."""
