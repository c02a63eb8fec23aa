"""The recorded configuration of an MCS-1 stream, found in any of its metadata layouts."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, Protocol, Self, TypeVar

from spotlab.core.errors import ConfigurationError


def recorded_config(
    meta: Mapping[str, Any], family: str, code: str, keys: Sequence[str]
) -> Mapping[str, Any]:
    """The configuration dictionary a family's decoder is rebuilt from.

    Parameters
    ----------
    meta : mapping
        The driver's ``metadata()``, the stream's ``StreamSpec.to_dict()``, or the
        configuration dictionary itself (recognised by holding every one of ``keys``).
    family : str
        The family name the metadata must carry, if it carries one (``"selspot"``...).
    code : str
        The family's wire code, for messages (``"SPX"``...).
    keys : sequence of str
        Entries a bare configuration dictionary holds.

    Raises
    ------
    ConfigurationError
        If the metadata belongs to another family or holds no configuration.
    """
    found = meta.get("family")
    if found not in (None, family):
        raise ConfigurationError(f"metadata of a {found!r} stream, not a {family} one")
    config: Any = meta.get("config")
    if config is None:
        spec = meta.get("spec", meta)
        config = spec.get("metadata", {}).get("config") if isinstance(spec, Mapping) else None
    if config is None and all(k in meta for k in keys):
        config = meta
    if not isinstance(config, Mapping):
        raise ConfigurationError(
            f"metadata holds no {code} configuration (expected a 'config' entry with "
            f"{', '.join(keys)}); keys found: {sorted(meta)}"
        )
    return config


class _FromDict(Protocol):
    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Self:
        """The configuration of its ``to_dict()``."""


ConfigT = TypeVar("ConfigT", bound=_FromDict)


def as_config(config: ConfigT | Mapping[str, Any], config_class: type[ConfigT]) -> ConfigT:
    """``config`` itself if it is a ``config_class``, else ``config_class.from_dict(config)``."""
    if isinstance(config, config_class):
        return config
    return config_class.from_dict(config)  # type: ignore[arg-type]
