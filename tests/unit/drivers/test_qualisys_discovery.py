"""``spotlab devices --probe`` finds QTM real-time servers: at 127.0.0.1:22223, at the
addresses of ``$SPOTLAB_QTM`` and at a lab file's qualisys devices; a listener that is not
QTM and a closed port are not reported. Only the qualisys family probes here (the serial
families are left out: other programs' pseudo-terminals are not touched)."""

from __future__ import annotations

import json
import socket
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest

from spotlab.console.cli import main
from spotlab.console.commands import devices
from spotlab.drivers.qualisys import QualisysDriver
from spotlab.drivers.qualisys.discovery import ENV, probe_addresses, probe_server
from spotlab.simulators.qualisys import QualisysServer, QualisysSimOptions


@pytest.fixture
def server() -> Iterator[QualisysServer]:
    with QualisysServer(QualisysSimOptions(markers=12, cameras=3, rate_hz=150.0)) as s:
        yield s


@pytest.fixture
def only_qualisys(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(devices, "available_families", lambda: ["qualisys"])
    monkeypatch.setattr(devices, "simulator_ports", lambda: [])


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def test_probe_reads_the_servers_parameters(
    server: QualisysServer, monkeypatch: pytest.MonkeyPatch
) -> None:
    closed = f"127.0.0.1:{_free_port()}"
    monkeypatch.setenv(ENV, f"{server.address}, {closed}")
    assert probe_addresses(["example.org", server.address]) == [
        "127.0.0.1:22223", server.address, closed, "example.org:22223"
    ]  # fmt: skip
    found = [d for d in QualisysDriver.detect() if d.port == server.address]
    assert len(found) == 1
    dev = found[0]
    assert dev.family == "qualisys" and dev.description.startswith("QTM Version is")
    assert dev.extra["rate_hz"] == 150.0 and dev.extra["cameras"] == 3
    assert dev.extra["labels"] == list(server.scene.labels)


def test_a_listener_that_is_not_qtm_is_not_reported() -> None:
    with socket.socket() as listener:
        listener.bind(("127.0.0.1", 0))
        listener.listen(1)
        address = f"127.0.0.1:{listener.getsockname()[1]}"

        def talk() -> None:
            conn, _ = listener.accept()
            with conn:
                conn.sendall(b"SSH-2.0-OpenSSH_9.6\r\n")

        thread = threading.Thread(target=talk)
        thread.start()
        assert probe_server(address) is None
        thread.join(5)
    assert probe_server(f"127.0.0.1:{_free_port()}") is None


def test_devices_probe_finds_qtm_by_env_and_lab_file(
    server: QualisysServer,
    only_qualisys: None,
    monkeypatch: pytest.MonkeyPatch,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    monkeypatch.setenv(ENV, server.address)
    with QualisysServer(QualisysSimOptions(markers=4)) as other:
        lab = tmp_path / "lab.toml"
        lab.write_text(f'[[device]]\nfamily = "qualisys"\nport = "{other.address}"\n')
        assert main(["devices", "--probe", "--lab", str(lab), "--json"]) == 0
        result = json.loads(capsys.readouterr().out)
        assert main(["devices", "--probe"]) == 0
        text = capsys.readouterr().out
    ports = {d["port"] for d in result["devices"] if d["family"] == "qualisys"}
    assert {server.address, other.address} <= ports
    assert f"qualisys at {server.address}: QTM Version is" in text


def test_devices_probe_finds_qtm_at_the_default_port(
    only_qualisys: None, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.delenv(ENV, raising=False)
    try:
        qtm = QualisysServer(QualisysSimOptions(markers=4, port=22223)).start()
    except OSError:
        pytest.skip("port 22223 is taken on this machine")
    try:
        assert main(["devices", "--probe", "--json"]) == 0
    finally:
        qtm.stop()
    found = json.loads(capsys.readouterr().out)["devices"]
    assert [d["port"] for d in found] == ["127.0.0.1:22223"]
