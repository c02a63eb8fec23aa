"""The error of a processing step whose input cannot be used.

Kept free of numpy (and of the rest of spotlab) so that the command line can import it
at start-up: :class:`spotlab.console.errors.CommandError` is this class.
"""

from __future__ import annotations

#: Exit code of the command line for a failure (see :mod:`spotlab.console.errors`).
EXIT_FAILURE = 1


class InputError(Exception):
    """An input of a processing step (a file, a value, an option) cannot be used.

    The message names the input and the cause, and is shown to the user as it is (the
    command line prints it as one line and exits with ``exit_code``).

    Parameters
    ----------
    message : str
        What went wrong, naming the input.
    exit_code : int, optional
        Exit code of the command line when the failure ends a command (1).
    """

    def __init__(self, message: str, exit_code: int = EXIT_FAILURE) -> None:
        super().__init__(message)
        self.exit_code = exit_code
