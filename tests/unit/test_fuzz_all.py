"""A short run of the mutation fuzzer of every decoder and reader (``make fuzz`` runs
1 000 000 inputs per target): nothing but spotlab's documented errors comes out."""

from __future__ import annotations

import os

import pytest

from spotlab.testing.fuzz import TARGETS, fuzz

INPUTS = int(os.environ.get("SPOTLAB_FUZZ_EXAMPLES", "300"))


@pytest.mark.parametrize("target", list(TARGETS))
def test_mutated_inputs_raise_only_documented_errors(target: str) -> None:
    result = fuzz(target, INPUTS, seed=11)
    assert result.inputs == INPUTS
    assert result.unexpected == 0, result.to_dict()


def test_the_readers_refuse_damage_with_documented_errors() -> None:
    # The readers' inputs are often unreadable after damage: they must say so (a
    # documented error), which shows the fuzzer reaches their checks.
    assert fuzz("trc", 100, seed=3).documented > 50
    assert fuzz("rig", 100, seed=3).documented > 50
