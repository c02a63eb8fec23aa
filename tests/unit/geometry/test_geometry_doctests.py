"""The Examples sections of the camera and DLT docstrings run as written."""

from __future__ import annotations

import doctest
from types import ModuleType

import pytest

from spotlab.calibration import dlt
from spotlab.geometry import camera


@pytest.mark.parametrize("module", [camera, dlt], ids=lambda m: m.__name__)
def test_examples(module: ModuleType) -> None:
    failures, tried = doctest.testmod(module, optionflags=doctest.NORMALIZE_WHITESPACE)
    assert tried > 0
    assert failures == 0
