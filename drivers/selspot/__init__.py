"""Lateral-photodiode (SELSPOT-style) camera systems: SPX protocol over MCS-1."""
