"""Compiled kernels: load one, or say that its numpy twin runs instead.

A kernel is a C extension module built from a ``_c_*.c`` file beside the Python module
that uses it (see ``setup.py``). Every kernel has a numpy twin giving the same results;
the twin runs where the kernel was not built (no C compiler at install time) or when
``SPOTLAB_NO_NATIVE=1`` is set in the environment (to compare the two, or to rule the
kernel out when hunting a fault).
"""

from __future__ import annotations

import importlib
import os
from types import ModuleType

__all__ = ["disabled", "load"]

#: Environment variable that, set to ``1``, keeps every kernel unloaded.
NO_NATIVE_ENV = "SPOTLAB_NO_NATIVE"


def disabled() -> bool:
    """Whether ``SPOTLAB_NO_NATIVE=1`` asks for the numpy twins.

    Returns
    -------
    bool
        True when the environment variable is set to ``1``.
    """
    return os.environ.get(NO_NATIVE_ENV, "") == "1"


def load(module: str) -> ModuleType | None:
    """Import one compiled kernel.

    Parameters
    ----------
    module : str
        Its full name, e.g. ``"spotlab.kinematics._c_gcv"``.

    Returns
    -------
    ModuleType or None
        The kernel, or None when it was not built or the twins are asked for.
    """
    if disabled():
        return None
    try:
        return importlib.import_module(module)
    except ImportError:
        return None
