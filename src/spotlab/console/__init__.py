"""Command line and operator tools."""
