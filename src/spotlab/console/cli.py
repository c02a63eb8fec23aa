"""The ``spotlab`` command: one entry point, one module per subcommand.

User errors end as one line on stderr and a non-zero exit code; a traceback
means a bug in spotlab.
"""

from __future__ import annotations

import argparse
import importlib
import signal
import sys
import threading
from collections.abc import Sequence

from spotlab import __version__
from spotlab.console.errors import (
    EXIT_FAILURE,
    EXIT_INTERRUPTED,
    EXIT_USAGE,
    CommandError,
    report,
)

# Modules of spotlab.console.commands, each with add_parser(subparsers) and run(args),
# with the one-line help ``spotlab --help`` shows for them. Only the module of the
# command that runs is imported (its imports take seconds: numpy, scipy, matplotlib);
# the others appear in ``spotlab --help`` by this line alone (tests/unit/console check
# that it is the one their add_parser gives).
COMMANDS: dict[str, str] = {
    "devices": "list serial ports and, with --probe, the devices that answer on them",
    "sim": "run a simulated device (pseudo-terminal or TCP) until stopped",
    "record": "record devices into a journal (raw wire bytes, crash-safe)",
    "info": "summarise a recording: frames, losses, checksum errors, gaps, rate",
    "replay": "decode a recording again and put every stream on session time",
    "calibrate": "calibrate a camera rig from a wand dance and a reference object",
    "reconstruct": "triangulate marker trajectories from observations and a calibration",
    "model": "learn, show, check or init a marker model for identification",
    "export": "write a recording or a trial file as C3D or TRC",
    "demo": "simulated system end to end: record with faults, decode, report",
    "bench": "run a device's conformance suite and measure its timing, with a report",
    "hil": "run a hardware-in-the-loop scenario of simulators, or list the shipped ones",
    "udev": "install or check the udev rules for USB-serial adapters and OAK cameras",
    "console": "serve the lab acquisition console, a live web page (devices, views, trials)",
}


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # type: ignore[override]
        # "spotlab: error: record: ..." for a subcommand, "spotlab: error: ..." else.
        command = self.prog.partition(" ")[2]
        report(f"{command}: {message}" if command else message)
        sys.exit(EXIT_USAGE)


def _command_of(argv: Sequence[str]) -> str | None:
    """The subcommand named in ``argv`` (the first word not an option), if known."""
    for word in argv:
        if not word.startswith("-"):
            return word if word in COMMANDS else None
    return None


def build_parser(command: str | None = "*") -> argparse.ArgumentParser:
    """The argument parser: every subcommand, fully defined for ``command`` only.

    Parameters
    ----------
    command : str or None
        The subcommand whose module is imported and whose options are defined; the
        others get their help line only. ``"*"`` (default): all of them in full.
    """
    parser = _Parser(
        prog="spotlab",
        description="Acquisition suite for optoelectronic motion measurement.",
    )
    parser.add_argument("--version", action="version", version=f"spotlab {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True
    for name, help_line in COMMANDS.items():
        if command in ("*", name):
            module = importlib.import_module(f"spotlab.console.commands.{name}")
            module.add_parser(sub)
        else:
            sub.add_parser(name, help=help_line, add_help=False)
    return parser


def _subparser(parser: argparse.ArgumentParser, command: str) -> argparse.ArgumentParser:
    """The parser of subcommand ``command`` (``parser`` itself if there is none)."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            found: argparse.ArgumentParser = action.choices.get(command, parser)
            return found
    return parser


def _spotlab_error() -> type[Exception]:
    """spotlab's error base class, imported only when an error is being matched (it
    brings numpy, which ``spotlab --version`` and ``--help`` do without)."""
    from spotlab.core.errors import SpotlabError

    return SpotlabError


_sigint_seen = threading.Event()


def _on_sigint(signum: int, frame: object) -> None:
    """Python's own Ctrl-C handling, remembering that it happened."""
    _sigint_seen.set()
    raise KeyboardInterrupt


def _interrupted(exc: BaseException) -> bool:
    """Whether ``exc`` comes from a Ctrl-C: a KeyboardInterrupt in its chain of causes, or
    one taken while it was being raised (an extension module being imported turns the
    interrupt into an ImportError of its own, e.g. numpy's "PyCapsule_Import could not
    import module 'datetime'")."""
    if _sigint_seen.is_set():
        return True
    seen: set[int] = set()
    current: BaseException | None = exc
    while current is not None and id(current) not in seen:
        if isinstance(current, KeyboardInterrupt):
            return True
        seen.add(id(current))
        current = current.__cause__ or current.__context__
    return False


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit code."""
    argv = list(sys.argv[1:] if argv is None else argv)
    own_handler = (
        threading.current_thread() is threading.main_thread()
        and signal.getsignal(signal.SIGINT) is signal.default_int_handler
    )
    if own_handler:
        _sigint_seen.clear()
        signal.signal(signal.SIGINT, _on_sigint)
    try:
        return _main(argv)
    finally:
        if own_handler and signal.getsignal(signal.SIGINT) is _on_sigint:
            signal.signal(signal.SIGINT, signal.default_int_handler)


def _main(argv: list[str]) -> int:
    """:func:`main` with its Ctrl-C handler in place."""
    try:
        parser = build_parser(_command_of(argv))
        args, extra = parser.parse_known_args(argv)
        if extra:  # named by the subcommand that was given them
            _subparser(parser, args.command).error(f"unrecognized arguments: {' '.join(extra)}")
        code = args.run(args)
    except SystemExit:  # --help, --version and usage errors: argparse has spoken
        raise
    except KeyboardInterrupt:
        report("interrupted")
        return EXIT_INTERRUPTED
    except ImportError as exc:
        # Ctrl-C while a C extension was being imported: numpy re-raises the
        # interrupt as an ImportError of its own.
        if not _interrupted(exc):
            raise
        report("interrupted")
        return EXIT_INTERRUPTED
    except CommandError as exc:
        report(str(exc))
        return exc.exit_code
    except _spotlab_error() as exc:
        report(str(exc))
        return EXIT_FAILURE
    except BrokenPipeError:
        return EXIT_FAILURE
    except OSError as exc:
        # A file or device the command was given cannot be used: name it, once.
        where = f": {exc.filename}" if exc.filename is not None else ""
        report(f"{exc.strerror or exc}{where}")
        return EXIT_FAILURE
    return int(code or 0)


if __name__ == "__main__":
    sys.exit(main())
