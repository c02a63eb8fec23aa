"""The Examples sections of the synchroniser's docstrings run as written."""

from __future__ import annotations

import doctest
import importlib

import pytest

MODULES = [
    "spotlab.acquisition.synchroniser.sample_times",
    "spotlab.acquisition.synchroniser.gaps",
    "spotlab.acquisition.synchroniser.resample",
    "spotlab.acquisition.synchroniser.synchroniser",
]


@pytest.mark.parametrize("name", MODULES)
def test_examples(name: str) -> None:
    module = importlib.import_module(name)
    failures, tried = doctest.testmod(module, optionflags=doctest.NORMALIZE_WHITESPACE)
    assert tried > 0
    assert failures == 0
