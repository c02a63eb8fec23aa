"""The device options ``spotlab record`` and ``spotlab bench`` both take.

``PORT --driver FAMILY`` or ``--device FAMILY=PORT[,key=value...]`` (repeatable) name
the devices; ``--cameras``, ``--leds``, ``--rate`` and ``--baud`` give settings to
devices that do not say (:data:`spotlab.console.device_settings.GLOBAL_OPTIONS`).
"""

from __future__ import annotations

import argparse

from spotlab.drivers import available_families

__all__ = ["add_device_arguments", "add_setting_arguments"]


def add_device_arguments(p: argparse.ArgumentParser, device_help: str) -> None:
    """``port``, ``--driver FAMILY`` and ``--device FAMILY=PORT[,key=value...]``."""
    p.add_argument("port", nargs="?", help="device path or URL (with --driver)")
    p.add_argument("--driver", help=f"device family of PORT ({', '.join(available_families())})")
    p.add_argument(
        "--device",
        action="append",
        default=[],
        metavar="FAMILY=PORT[,key=value...]",
        help=device_help,
    )


def add_setting_arguments(p: argparse.ArgumentParser, baud_help: str) -> None:
    """``--cameras``, ``--leds``, ``--rate`` and ``--baud``, for devices that do not say."""
    p.add_argument("--cameras", type=int, help="cameras, for devices that do not say")
    p.add_argument("--leds", type=int, help="LEDs (markers), for devices that do not say")
    p.add_argument("--rate", type=float, help="frame rate in Hz, for devices that do not say")
    p.add_argument("--baud", help=baud_help)
