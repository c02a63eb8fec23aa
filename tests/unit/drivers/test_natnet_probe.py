"""``spotlab devices --probe`` finds a NatNet server (Motive's command port, 1510 by default).

The simulated Motive listens on a free port named by ``SPOTLAB_NATNET_PROBE``; the
command's probe is narrowed to the NatNet family (no serial port of another test or
simulator is touched).
"""

from __future__ import annotations

import json
import socket
import time

import pytest

from spotlab.console.cli import main
from spotlab.console.commands import devices
from spotlab.drivers.natnet import NatNetDriver
from spotlab.drivers.natnet.probe import DEFAULT_ADDRESS, PROBE_ENV, probe_addresses
from spotlab.simulators.natnet import NatNetServer
from spotlab.simulators.natnet_scene import NatNetScene


def test_the_default_address_is_motives_command_port_on_this_machine(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.delenv(PROBE_ENV, raising=False)
    assert probe_addresses() == [DEFAULT_ADDRESS] == ["127.0.0.1:1510"]
    monkeypatch.setenv(PROBE_ENV, " 10.0.0.5, 127.0.0.1:3510 ")
    assert probe_addresses() == ["10.0.0.5", "127.0.0.1:3510"]


def test_devices_probe_finds_the_server_and_leaves_it_alone(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    scene = NatNetScene(markers=4, cameras=2, rate_hz=100.0)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as silent:
        silent.bind(("127.0.0.1", 0))  # bound, never answers
        quiet = f"127.0.0.1:{silent.getsockname()[1]}"
        with NatNetServer(scene, version=(3, 1)) as srv:
            monkeypatch.setenv(PROBE_ENV, f"{quiet},{srv.address},no-port:x")
            monkeypatch.setattr(devices, "available_families", lambda: ["natnet"])
            monkeypatch.setattr(devices, "simulator_ports", lambda: [])
            t0 = time.monotonic()
            assert main(["devices", "--probe", "--json"]) == 0
            took = time.monotonic() - t0
            time.sleep(0.1)
            assert srv.clients == {}, "the probe disconnects"
    (found,) = json.loads(capsys.readouterr().out)["devices"]
    assert found["family"] == "natnet" and found["port"] == srv.address
    assert "NatNet 3.1 server 'spotlab-natnet-sim'" in found["description"]
    assert found["extra"]["clock_hz"] == 10_000_000 and not found["extra"]["multicast"]
    assert took < 3.0


def test_detect_finds_nothing_where_nothing_listens(monkeypatch: pytest.MonkeyPatch) -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        free = s.getsockname()[1]
    monkeypatch.setenv(PROBE_ENV, f"127.0.0.1:{free}")
    assert NatNetDriver.detect() == []
