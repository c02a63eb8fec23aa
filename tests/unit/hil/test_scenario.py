"""Scenario files: what they hold, and one clear error naming file, line and key."""

from __future__ import annotations

from pathlib import Path

import pytest

from spotlab.hil.catalog import describe, shipped
from spotlab.hil.processes import sim_argv
from spotlab.hil.scenario import ScenarioError, load_scenario

GOOD = """\
name = "two systems"
duration = 3.0
seed = 4

[motion]
kind = "wand"

[[device]]
family = "timer"
name = "timer"
rate = 100
[device.sim]
inputs = { 0 = "selspot0" }
clock_drift_ppm = 30

[[device]]
family = "selspot"
name = "selspot0"
rate = 200
cameras = 2
[device.sim]
faults = "bitflip@1"
clock_steps = ["2:0.001"]

[processing]
steps = ["timestamps"]

[criteria]
sync_error_us = { max = 50 }
[criteria.selspot0]
lost_frames = { max = 2 }
rate_hz = { min = 199, max = 201 }
"""


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "s.toml"
    path.write_text(text)
    return path


def _error(tmp_path: Path, text: str) -> str:
    with pytest.raises(ScenarioError) as info:
        load_scenario(_write(tmp_path, text), {"selspot": ("rate", "cameras", "leds")})
    return str(info.value)


def test_a_scenario_is_read_with_its_wiring_and_criteria(tmp_path: Path) -> None:
    s = load_scenario(_write(tmp_path, GOOD))
    assert s.name == "two systems" and s.duration_s == 3.0 and s.seed == 4
    assert [d.name for d in s.devices] == ["timer", "selspot0"]
    assert s.wiring == {"selspot0": 0}
    assert s.steps == ("timestamps",) and s.motion == "wand"
    by = {c.figure: c for c in s.criteria}
    assert by["selspot0.rate_hz"].holds(200.0) and not by["selspot0.rate_hz"].holds(198.0)
    assert not by["sync_error_us"].holds(None)
    assert by["selspot0.lost_frames"].describe() == "selspot0.lost_frames <= 2"


def test_simulator_arguments(tmp_path: Path) -> None:
    s = load_scenario(_write(tmp_path, GOOD))
    timer = sim_argv(s.devices[0], s, 4, tmp_path)
    assert timer[:3] == ["sim", "timer", "--pty"]
    assert "--input" in timer and "0=selspot0" in timer and "--clock-drift-ppm" in timer
    selspot = sim_argv(s.devices[1], s, 4, tmp_path)
    assert selspot[selspot.index("--seed") + 1] == "5"  # seed + the device's index
    assert selspot[selspot.index("--motion") + 1] == "wand"
    assert selspot[selspot.index("--clock-step") + 1] == "2:0.001"
    assert selspot[selspot.index("--lab-name") + 1] == "selspot0"


@pytest.mark.parametrize(
    ("old", "new", "where"),
    [
        ("seed = 4", "seed = 4\nbogus = 1", ":4: bogus: unknown key"),
        ("cameras = 2", "cameras = 2\nflavour = 1", ":21: device[1].flavour: unknown key"),
        ('clock_steps = ["2:0.001"]', "colour = 2", ":23: device[1].sim.colour: unknown key"),
        ("lost_frames = {", "lost_framez = {", ":31: criteria.selspot0.lost_framez: no such"),
        ("sync_error_us = {", "sync_errors_us = {", ":29: criteria.sync_errors_us: no such"),
        ('steps = ["timestamps"]', "steps = []", ":29: criteria.sync_error_us: this figure"),
        ('0 = "selspot0"', '0 = "selspot9"', ":13: device[0].sim.inputs.0: no other device"),
        ('family = "selspot"', 'family = "vicon"', ":17: device[1].family: expected one of"),
        ("duration = 3.0", "duration = -1", ":2: duration: must be positive"),
        ('kind = "wand"', 'c3d = "nowhere.c3d"', ":6: motion.c3d: no such file"),
        ("rate = 200", "rate = [1, 2]", ":19: device[1].rate: expected a number"),
        ('steps = ["timestamps"]', 'steps = ["labelling"]', "takes a single centroid device"),
        ('steps = ["timestamps"]', 'steps = ["export"]', "'export' writes the reconstruction"),
    ],
)
def test_bad_input_names_file_line_and_key(tmp_path: Path, old: str, new: str, where: str) -> None:
    assert old in GOOD
    message = _error(tmp_path, GOOD.replace(old, new, 1))
    assert message.startswith(str(tmp_path / "s.toml") + ":"), message
    assert where in message, message


def test_not_toml_and_two_devices_of_one_name(tmp_path: Path) -> None:
    assert "not TOML" in _error(tmp_path, "name = ")
    twice = GOOD.replace('name = "timer"', 'name = "selspot0"').replace('"selspot0" }', '"x" }')
    assert "names two devices" in _error(tmp_path, twice)


def test_every_shipped_scenario_loads() -> None:
    found = shipped()
    assert {"gait-lab", "fault-storm"} <= set(found)
    for path in found.values():
        name, duration, description = describe(path)
        assert name and duration > 0 and description
        load_scenario(path)  # needs ../shared/data for the gait lab's C3D
