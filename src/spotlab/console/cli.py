"""The ``spotlab`` command: one entry point, one module per subcommand.

User errors end as one line on stderr and a non-zero exit code; a traceback
means a bug in spotlab.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

from spotlab import __version__
from spotlab.console.errors import (
    EXIT_FAILURE,
    EXIT_INTERRUPTED,
    EXIT_USAGE,
    CommandError,
    report,
)
from spotlab.core.errors import SpotlabError

# Modules of spotlab.console.commands, each with add_parser(subparsers) and run(args).
COMMANDS: tuple[str, ...] = (
    "devices",
    "sim",
    "record",
    "info",
    "replay",
    "calibrate",
    "reconstruct",
    "model",
    "export",
    "demo",
    "udev",
)


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # type: ignore[override]
        report(f"{self.prog}: {message}")
        sys.exit(EXIT_USAGE)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with every subcommand."""
    parser = _Parser(
        prog="spotlab",
        description="Acquisition suite for optoelectronic motion measurement.",
    )
    parser.add_argument("--version", action="version", version=f"spotlab {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True
    for name in COMMANDS:
        module = importlib.import_module(f"spotlab.console.commands.{name}")
        module.add_parser(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        code = args.run(args)
    except KeyboardInterrupt:
        report("interrupted")
        return EXIT_INTERRUPTED
    except CommandError as exc:
        report(str(exc))
        return exc.exit_code
    except SpotlabError as exc:
        report(str(exc))
        return EXIT_FAILURE
    except (FileNotFoundError, PermissionError, IsADirectoryError) as exc:
        report(f"{exc.strerror}: {exc.filename}")
        return EXIT_FAILURE
    except BrokenPipeError:
        return EXIT_FAILURE
    return int(code or 0)


if __name__ == "__main__":
    sys.exit(main())
