"""Import pylsl on first use, with an error that says how to get it."""

from __future__ import annotations

from types import ModuleType

from spotlab.core.errors import ConfigurationError


def pylsl_module() -> ModuleType:
    """The ``pylsl`` module, imported now.

    Raises
    ------
    ConfigurationError
        If pylsl (or the liblsl it bundles) is not installed.
    """
    try:
        import pylsl
    except (ImportError, RuntimeError) as exc:
        raise ConfigurationError(
            f"LSL needs pylsl, which is not usable here ({exc}); "
            "install it with: pip install 'spotlab[lsl]'"
        ) from exc
    return pylsl
