"""Byte-level device simulators, scene model, transports and fault injection."""
