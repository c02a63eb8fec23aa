"""The simulators of a scenario, each its own ``spotlab sim`` process on a real transport.

Every simulator writes its truth (and, for the serial families, its fault log) into
the run's folder and publishes its frame pulses in the run's lab folder, where a
timer's inputs see them. :func:`start_simulators` waits for each to print its
address; one that does not start stops the others and is reported with the line of
its ``[[device]]`` table.
"""

from __future__ import annotations

import contextlib
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from spotlab.hil.scenario import SERIAL_FAMILIES, Scenario, ScenarioError, SimDevice
from spotlab.hil.toml_lines import line_of

CLI: tuple[str, ...] = (sys.executable, "-m", "spotlab.console.cli")
#: Settings a device's simulator takes from the device's own settings.
SIM_SETTINGS = {"selspot": ("rate", "cameras", "leds"), "timer": ("rate",),
                "centroid": ("rate", "cameras"), "qualisys": (), "natnet": ()}  # fmt: skip
START_TIMEOUT_S = 30.0
#: Families whose simulators publish frame pulses a timer's inputs can capture.
PULSING_FAMILIES = (*SERIAL_FAMILIES, "qualisys")


@dataclass
class RunningSim:
    """A simulator process and what it writes."""

    device: SimDevice
    proc: subprocess.Popen[bytes]
    address: str
    truth: Path
    fault_log: Path | None
    rig: Path | None
    stderr: Path


def _option(key: str) -> str:
    return "--" + key.replace("_", "-")


def sim_argv(device: SimDevice, scenario: Scenario, seed: int, folder: Path) -> list[str]:
    """``spotlab sim ...`` arguments of one device (without the executable)."""
    args = ["sim", device.family]
    port = device.sim.get("port")
    if device.family not in SERIAL_FAMILIES:  # TCP/UDP servers: --port (0: any free one)
        args += ["--port", str(port or 0)]
    else:
        args += ["--pty"] if device.transport == "pty" else ["--tcp", str(port or 0)]
    for key in SIM_SETTINGS[device.family]:
        if key in device.settings:
            args += [_option(key), str(device.settings[key])]
    args += ["--seed", str(device.sim.get("seed", seed + device.index))]
    suffix = ".csv" if device.family in ("selspot", "timer") else ".npz"
    args += ["--truth", str(folder / f"{device.name}.truth{suffix}")]
    if device.family in SERIAL_FAMILIES:
        args += ["--fault-log", str(folder / f"{device.name}.faults.json")]
    if device.family in PULSING_FAMILIES:
        args += ["--lab", str(folder / "lab"), "--lab-name", device.name]
    if device.family in ("selspot", "centroid"):
        args += ["--rig-out", str(folder / f"{device.name}.rig.toml")]
    if device.family == "centroid":
        args += ["--model-out", str(folder / f"{device.name}.model.json")]
    if device.family == "selspot" and scenario.motion is not None and "motion" not in device.sim:
        args += ["--motion", scenario.motion]
    for key, value in device.sim.items():
        if key in ("seed", "port"):
            continue
        if key == "inputs":
            for number, source in value.items():
                args += ["--input", f"{number}={source}"]
        elif key == "clock_steps":
            for step in value:
                args += ["--clock-step", str(step)]
        else:
            args += [_option(key), str(value)]
    return args


def _port_free(port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


def first_line(out: Path, proc: subprocess.Popen[bytes], timeout: float) -> str | None:
    """The first line a child writes to ``out`` (its address), or None if it exits or
    ``timeout`` s pass first."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        text = out.read_bytes()
        if b"\n" in text:
            return text.split(b"\n", 1)[0].decode().strip()
        if proc.poll() is not None:
            return None
        time.sleep(0.02)
    return None


def stop_simulators(sims: Sequence[RunningSim], wait_s: float = 15.0) -> dict[str, int]:
    """SIGTERM every simulator (they write their truth and fault log), wait; SIGKILL one
    that does not end. Returns the exit codes by stream name."""
    for sim in sims:
        if sim.proc.poll() is None:
            sim.proc.send_signal(signal.SIGTERM)
    codes = {}
    for sim in sims:
        try:
            sim.proc.wait(timeout=wait_s)
        except subprocess.TimeoutExpired:
            sim.proc.kill()
            sim.proc.wait()
        codes[sim.device.name] = int(sim.proc.returncode)
    return codes


def check_ports(scenario: Scenario) -> None:
    """Refuse a scenario whose fixed TCP ports are taken.

    Raises
    ------
    ScenarioError
        Naming the file, the line and the device's ``sim.port``.
    """
    text = scenario.path.read_text(encoding="utf-8")
    for device in scenario.devices:
        port = device.sim.get("port")
        if isinstance(port, int) and port > 0 and not _port_free(port):
            key: list[str | int] = ["device", device.index, "sim", "port"]
            raise ScenarioError(
                f"{scenario.path}:{line_of(text, key)}: device[{device.index}].sim.port: "
                f"port {port} on 127.0.0.1 is busy"
            )


def start_simulators(scenario: Scenario, seed: int, folder: Path) -> list[RunningSim]:
    """Start every simulator of ``scenario`` and wait for its address.

    Raises
    ------
    ScenarioError
        A tcp port is busy, or a simulator ended or printed nothing; naming the file,
        the line and the device (the others are stopped first).
    """
    text = scenario.path.read_text(encoding="utf-8")
    sims: list[RunningSim] = []

    def fail(device: SimDevice, key: list[str | int], message: str) -> ScenarioError:
        stop_simulators(sims)
        dotted = f"device[{device.index}]" + "".join(f".{k}" for k in key)
        line = line_of(text, ["device", device.index, *key])
        return ScenarioError(f"{scenario.path}:{line}: {dotted}: {message}")

    check_ports(scenario)  # before any starts: a busy port costs nothing
    (folder / "lab").mkdir(parents=True, exist_ok=True)
    try:
        for device in scenario.devices:
            out = folder / f"{device.name}.sim.stdout"
            err = folder / f"{device.name}.sim.stderr"
            argv = [*CLI, *sim_argv(device, scenario, seed, folder)]
            with open(out, "wb") as fo, open(err, "wb") as fe:
                proc = subprocess.Popen(argv, stdout=fo, stderr=fe, stdin=subprocess.DEVNULL)
            suffix = ".csv" if device.family in ("selspot", "timer") else ".npz"
            sims.append(
                RunningSim(
                    device, proc, "", folder / f"{device.name}.truth{suffix}",
                    folder / f"{device.name}.faults.json" if device.family in SERIAL_FAMILIES
                    else None,
                    folder / f"{device.name}.rig.toml"
                    if device.family in ("selspot", "centroid") else None,
                    err,
                )
            )  # fmt: skip
        for sim in sims:
            address = first_line(folder / f"{sim.device.name}.sim.stdout", sim.proc,
                                  START_TIMEOUT_S)  # fmt: skip
            if not address:
                lines = [ln for ln in sim.stderr.read_text(errors="replace").splitlines() if ln]
                why = lines[-1].removeprefix("spotlab: error: ") if lines else "no address"
                raise fail(sim.device, [], f"the {sim.device.family} simulator did not start: "
                                           f"{why}")  # fmt: skip
            sim.address = address
    except BaseException:
        with contextlib.suppress(Exception):
            stop_simulators(sims)
        raise
    return sims


__all__ = ["RunningSim", "check_ports", "sim_argv", "start_simulators", "stop_simulators"]
