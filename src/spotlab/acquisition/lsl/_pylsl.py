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
        liblsl's log level (-3 errors only ... 0 info; default: liblsl's own).
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
    if log_level is not None:
        lines += ["[log]", f"level = {int(log_level)}"]
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
