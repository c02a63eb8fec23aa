"""Import pylsl on first use, with an error that says how to get it."""

from __future__ import annotations

import os
from pathlib import Path
from types import ModuleType

from spotlab.core.errors import ConfigurationError

#: liblsl's log level unless told otherwise: errors only. Its default (info) prints
#: lines such as "Loaded default config" on the user's terminal.
QUIET_LOG_LEVEL = -3


def _config_files() -> list[Path]:
    """Where liblsl looks for its configuration file, in its order."""
    found = [Path(os.environ["LSLAPICFG"])] if os.environ.get("LSLAPICFG") else []
    return [*found, Path("lsl_api.cfg"), Path.home() / "lsl_api" / "lsl_api.cfg",
            Path("/etc/lsl_api/lsl_api.cfg")]  # fmt: skip


def pylsl_module() -> ModuleType:
    """The ``pylsl`` module, imported now, with liblsl's log quiet (errors only) when
    no liblsl configuration file says otherwise.

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
    global _quieted
    if not _quieted:
        _quieted = True
        setter = getattr(pylsl, "set_config_content", None)
        if setter is not None and not any(path.is_file() for path in _config_files()):
            try:
                setter(f"[log]\nlevel = {QUIET_LOG_LEVEL}\n")
            except (AttributeError, RuntimeError):
                pass  # an old liblsl: its own log level stays
    return pylsl


_quieted = False


def configure(
    known_peers: tuple[str, ...] = (), *, log_level: int | None = None, session_id: str = ""
) -> str:
    """Set liblsl's configuration for this process, instead of an ``lsl_api.cfg`` file.

    liblsl reads its configuration once, at the first LSL call of the process,
    so call this before any outlet, inlet or resolve. Where multicast discovery
    does not work (containers, some CI runners, firewalled networks), name the
    hosts to query by unicast in ``known_peers``: ``("127.0.0.1",)`` for
    streams on this machine. The same settings go in a file named by the
    environment variable ``LSLAPICFG`` (see docs/lsl.md).

    Parameters
    ----------
    known_peers : tuple of str, optional
        Host names or addresses queried directly when resolving streams.
    log_level : int, optional
        liblsl's log level (-3 errors only ... 0 info; default -3, errors only).
    session_id : str, optional
        LSL session id: only streams of the same id see each other.

    Returns
    -------
    str
        The configuration text given to liblsl.

    Raises
    ------
    ConfigurationError
        If pylsl is missing or too old to take its configuration from a string.
    """
    lines = []
    if known_peers:
        lines += ["[lab]", "KnownPeers = {" + ", ".join(known_peers) + "}"]
    if session_id:
        lines += ([] if known_peers else ["[lab]"]) + [f"SessionID = {session_id}"]
    level = QUIET_LOG_LEVEL if log_level is None else int(log_level)
    lines += ["[log]", f"level = {level}"]
    text = "\n".join(lines) + "\n"
    pylsl = pylsl_module()
    setter = getattr(pylsl, "set_config_content", None)
    if setter is None:
        raise ConfigurationError("this pylsl cannot be configured from a string; use LSLAPICFG")
    try:
        setter(text)
    except (AttributeError, RuntimeError) as exc:
        raise ConfigurationError(f"liblsl refused its configuration: {exc}") from exc
    return text
