"""Decoders for recorded streams, found through the driver table."""

from __future__ import annotations

import importlib
from pathlib import Path
from typing import Any

from spotlab.core.errors import RecordingError
from spotlab.core.wire import StreamDecoder
from spotlab.drivers import DRIVERS, load_driver
from spotlab.io.journal import is_journal

#: The suffix a recording journal is taken for, whatever its name.
JOURNAL_SUFFIX = ".spj"


def decoder_for(metadata: dict[str, Any]) -> StreamDecoder:
    """Build the decoder of a recorded stream from its metadata.

    Parameters
    ----------
    metadata : dict
        What the driver's ``metadata()`` wrote into the recording; must name the ``family``.

    Raises
    ------
    RecordingError
        If the family is unknown to this spotlab or its metadata is incomplete.
    """
    family = metadata.get("family")
    if not isinstance(family, str):
        raise RecordingError("a stream in the recording does not name its device family")
    if family in DRIVERS:
        module = importlib.import_module(DRIVERS[family][0])
    else:
        module = importlib.import_module(load_driver(family).__module__)
    factory = getattr(module, "decoder_from_metadata", None)
    if factory is None:
        raise RecordingError(
            f"driver {family!r} cannot decode recordings (no decoder_from_metadata)"
        )
    try:
        decoder: StreamDecoder = factory(metadata)
    except (KeyError, TypeError, ValueError) as exc:
        raise RecordingError(f"metadata of a {family!r} stream is incomplete: {exc}") from exc
    return decoder


def input_suffix(path: Path) -> str:
    """The format of an input file: ``".spj"`` for a recording journal, recognised by its
    magic bytes whatever its name, else the file name's suffix (lower case)."""
    return JOURNAL_SUFFIX if is_journal(path) else path.suffix.lower()
