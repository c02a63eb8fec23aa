"""``spotlab udev``: show, check and (only with --yes) install the udev rules."""

from spotlab.console.udev import add_udev_parser as add_parser
from spotlab.console.udev import run_udev as run

__all__ = ["add_parser", "run"]
