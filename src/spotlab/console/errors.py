"""How the command line reports failures: one clear line, a non-zero exit, no traceback."""

from __future__ import annotations

import sys

EXIT_OK = 0
EXIT_FAILURE = 1
EXIT_USAGE = 2
EXIT_INTERRUPTED = 130


class CommandError(Exception):
    """A user-facing failure of a command; its message is printed as it is."""

    def __init__(self, message: str, exit_code: int = EXIT_FAILURE) -> None:
        super().__init__(message)
        self.exit_code = exit_code


def report(message: str) -> None:
    """Print one error line on stderr, prefixed with the program name."""
    text = " ".join(str(message).split())
    print(f"spotlab: error: {text}", file=sys.stderr)
