"""The recorded configuration of an MCS-1 stream, in each of its metadata layouts."""

from __future__ import annotations

import pytest

from spotlab.core.errors import ConfigurationError
from spotlab.drivers.mcs1.metadata import recorded_config

CONFIG = {"cameras": 2, "leds": 8}


@pytest.mark.parametrize(
    "meta",
    [
        {"family": "selspot", "config": CONFIG},
        {"family": "selspot", "spec": {"metadata": {"config": CONFIG}}},
        {"metadata": {"config": CONFIG}},
        CONFIG,
    ],
)
def test_every_layout_gives_the_configuration(meta: dict) -> None:
    assert recorded_config(meta, "selspot", "SPX", ("cameras", "leds")) == CONFIG


def test_another_family_and_no_configuration_are_named() -> None:
    with pytest.raises(ConfigurationError, match="'timer' stream, not a selspot one"):
        recorded_config({"family": "timer", "config": CONFIG}, "selspot", "SPX", ("cameras",))
    with pytest.raises(ConfigurationError, match=r"no SPX configuration .* cameras, leds"):
        recorded_config({"cameras": 2}, "selspot", "SPX", ("cameras", "leds"))
