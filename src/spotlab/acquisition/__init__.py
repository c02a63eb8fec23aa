"""Acquisition: sessions of devices, sinks, recording and replay."""
