"""How the command line reports failures: one clear line, a non-zero exit, no traceback.

:class:`CommandError` is the processing layer's
:class:`~spotlab.processing.errors.InputError`: what ``spotlab.processing`` raises for an
input it cannot use is reported like a command's own user error.
"""

from __future__ import annotations

import sys

from spotlab.processing.errors import EXIT_FAILURE
from spotlab.processing.errors import InputError as CommandError

__all__ = ["EXIT_FAILURE", "EXIT_INTERRUPTED", "EXIT_OK", "EXIT_USAGE", "CommandError", "report"]

EXIT_OK = 0
EXIT_USAGE = 2
EXIT_INTERRUPTED = 130


def report(message: str) -> None:
    """Print one error line on stderr, prefixed with the program name."""
    text = " ".join(str(message).split())
    print(f"spotlab: error: {text}", file=sys.stderr)
