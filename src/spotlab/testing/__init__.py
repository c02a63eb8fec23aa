"""Conformance suites and pytest support for device families."""
