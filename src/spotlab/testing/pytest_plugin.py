"""pytest plugin: ``--hw FAMILY=PORT`` runs a family's conformance suite on real hardware.

Registered through the ``pytest11`` entry point, so it is active in any pytest
run where spotlab is installed. Without ``--hw`` the conformance suites run
against the simulators only.
"""

from __future__ import annotations

import pytest

from spotlab.core.errors import ConfigurationError


def pytest_addoption(parser: pytest.Parser) -> None:
    group = parser.getgroup("spotlab")
    group.addoption(
        "--hw",
        action="append",
        default=[],
        metavar="FAMILY=PORT",
        help="run the conformance suite of FAMILY against the real device at PORT "
        "(a device path or pyserial URL); may be given once per family",
    )


def hardware_ports(config: pytest.Config) -> dict[str, str]:
    """The ``--hw`` options as ``{family: port}``.

    Raises
    ------
    ConfigurationError
        If an option is not of the form ``FAMILY=PORT``.
    """
    ports: dict[str, str] = {}
    for item in config.getoption("--hw"):
        family, sep, port = str(item).partition("=")
        if not sep or not family or not port:
            raise ConfigurationError(f"--hw takes FAMILY=PORT, got {item!r}")
        ports[family] = port
    return ports
