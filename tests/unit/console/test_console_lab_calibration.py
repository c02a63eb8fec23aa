"""The console's calibration wizard on a lab file's own devices (not ``--sim``): a
video-centroid hub and a SELSPOT-style system, each a simulator in a process of its own
on a real pseudo-terminal, calibrated from the page's API as ``spotlab calibrate`` does.

The lab file names each device by a symbolic link, as a lab names an adapter by its
udev link: for the hub, the link is moved from the wand simulator to the L-frame
simulator between the two recordings (the operator puts the wand away and lays the
L-frame down). The SELSPOT system's wand simulator also holds the L-frame (LEDs 3-6,
static): its wand dance and L-frame recordings come from one process.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
import urllib.error
import urllib.request
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from spotlab.console.web.calibration_wizard import CalibrationWizard
from spotlab.console.web.lab_setup import plan_lab
from spotlab.io.lab_file import LabFileError, load_lab
from spotlab.processing.errors import InputError

CLI = (sys.executable, "-m", "spotlab.console.cli")


def _first_line(proc: subprocess.Popen[bytes], out: Path, timeout: float = 60.0) -> str:
    deadline = time.monotonic() + timeout
    while not out.read_text().endswith("\n"):
        if proc.poll() is not None or time.monotonic() > deadline:
            raise AssertionError(f"{proc.args}: no first line")
        time.sleep(0.05)
    return out.read_text().splitlines()[0]


@pytest.fixture
def spawn(tmp_path: Path) -> Iterator[Callable[..., tuple[subprocess.Popen[bytes], Path]]]:
    """Start a child process; (process, its stdout file). All are stopped at the end."""
    started: list[subprocess.Popen[bytes]] = []

    def start(name: str, *args: str) -> tuple[subprocess.Popen[bytes], Path]:
        out = tmp_path / f"{name}.out"
        with open(out, "wb") as o, open(tmp_path / f"{name}.err", "wb") as e:
            proc = subprocess.Popen([*CLI, *args], stdout=o, stderr=e, stdin=subprocess.DEVNULL)
        started.append(proc)
        return proc, out

    yield start
    for proc in started:
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
            try:
                proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


def _call(base: str, path: str, body: dict[str, Any] | None = None) -> tuple[int, Any]:
    data = None if body is None else json.dumps(body).encode()
    request = urllib.request.Request(base + path, data=data, method="POST" if data else "GET")
    try:
        with urllib.request.urlopen(request, timeout=30) as response:
            return response.status, json.loads(response.read())
    except urllib.error.HTTPError as exc:
        return exc.code, json.loads(exc.read())


def _until(what: Callable[[], Any], timeout: float, why: Callable[[], str]) -> Any:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if result := what():
            return result
        time.sleep(0.1)
    raise AssertionError(f"timed out: {why()}")


def _relink(link: Path, target: str) -> None:
    tmp = link.with_name(link.name + ".new")
    tmp.unlink(missing_ok=True)
    tmp.symlink_to(target)
    os.replace(tmp, link)


@pytest.mark.long
@pytest.mark.timeout(300)
def test_the_wizard_calibrates_a_lab_files_hub_and_selspot_system(
    tmp_path: Path, spawn: Callable[..., tuple[subprocess.Popen[bytes], Path]]
) -> None:
    # the L-frame's published coordinates (docs/calibration.md), mm
    (tmp_path / "lframe.csv").write_text(
        "marker,X,Y,Z\n1,0,0,10\n2,200,0,10\n3,600,0,10\n4,0,400,10\n"
    )
    common = ("--pty", "--cameras", "4", "--rate", "100")
    sims = {
        "hub_wand": spawn("hub_wand", "sim", "centroid", *common, "--motion", "wand",
                          "--markers", "3", "--seed", "1"),
        "hub_lframe": spawn("hub_lframe", "sim", "centroid", *common, "--motion", "lframe",
                            "--seed", "2"),
        "spx": spawn("spx", "sim", "selspot", *common, "--leds", "6", "--motion", "wand",
                     "--reflectance", "0", "--seed", "1"),
    }  # fmt: skip
    ports = {name: _first_line(proc, out) for name, (proc, out) in sims.items()}
    hub, spx = tmp_path / "hub-adapter", tmp_path / "selspot-adapter"
    _relink(hub, ports["hub_wand"])
    _relink(spx, ports["spx"])
    lab = tmp_path / "lab.toml"
    lab.write_text(
        f'[[device]]\nfamily = "centroid"\nport = "{hub}"\nname = "hub"\n\n'
        f'[[device]]\nfamily = "selspot"\nport = "{spx}"\ncameras = 4\nleds = 6\n\n'
        '[calibration]\nwand_length = 500\nframe_points = "lframe.csv"\n'
        "wand_markers = [1, 2]\nframe_markers = [3, 4, 5, 6]\n"
    )
    data = tmp_path / "data"
    console, out = spawn(
        "console", "console", "--lab", str(lab), "--port", "0", "--no-browser", "--data",
        str(data),
    )  # fmt: skip
    base = _first_line(console, out).rstrip("/")

    def why() -> str:
        return f"{_call(base, '/api/calibration')[1]}; {(tmp_path / 'console.err').read_text()}"

    def state() -> dict[str, Any]:
        return dict(_call(base, "/api/calibration")[1])

    assert state()["devices"] == ["hub", "selspot"]
    code, body = _call(
        base, "/api/calibration/wand", {"subject": "S", "session": "c", "seconds": 1}
    )
    assert code == 400 and "choose the device" in body["error"], body
    results = {}
    for device, session, seconds in (("hub", "hubcal", 6), ("selspot", "spxcal", 6)):
        body = {"subject": "S01", "session": session, "seconds": seconds, "device": device}
        code, got = _call(base, "/api/calibration/wand", body)
        assert code == 202 and got["device"] == device, got
        got = _until(lambda: (s := state())["step"] != "wand" and s, 60, why)
        assert got["step"] == "wand_done", got
        assert len(got["coverage"]) == 4 and min(got["coverage"].values()) > 0.02, got
        if device == "hub":  # the operator lays the L-frame down in the hub's view
            _relink(hub, ports["hub_lframe"])
        assert _call(base, "/api/calibration/lframe", {"seconds": 1})[0] == 202
        got = _until(lambda: (s := state())["step"] != "lframe" and s, 60, why)
        assert got["step"] == "lframe_done", got
        assert _call(base, "/api/calibration/run", {})[0] == 202
        got = _until(lambda: (s := state())["step"] != "calibrating" and s, 180, why)
        assert got["step"] == "calibrated", got.get("error")
        results[device] = got["report"]
        code, got = _call(base, "/api/calibration/accept", {})
        assert code == 200 and got["rig"] == f"S01/{session}/rig.toml", got
        assert (data / "S01" / session / "rig.toml").is_file()
        # the wizard's recordings hold the calibrated device alone
        for trial in ("calib_wand", "calib_lframe"):
            side = json.loads((data / "S01" / session / f"{trial}.json").read_text())
            assert side["state"] == "done" and list(side["frames"]) == [device], side
    assert results["hub"]["units"] == "px" and results["selspot"]["units"] == "counts"
    for device, report in results.items():
        assert [c["name"] for c in report["cameras"]] == ["cam1", "cam2", "cam3", "cam4"]
        # px for the hub, detector counts (of 4096) for the SELSPOT system
        limit = 1.0 if device == "hub" else 5.0
        assert all(0 < c["reprojection_rms"] < limit for c in report["cameras"]), report
    # the lab's devices are back
    _until(
        lambda: (
            {d["name"] for d in _call(base, "/api/devices")[1]["devices"]} == {"hub", "selspot"}
        ),
        30,
        why,
    )


def test_a_lab_files_calibration_table_and_the_wizards_choice(tmp_path: Path) -> None:
    """The ``[calibration]`` table is read and checked; the wizard offers the lab's hubs
    and SELSPOT systems and says what it lacks (in process, no device)."""
    lab = tmp_path / "lab.toml"
    devices = (
        '[[device]]\nfamily = "centroid"\nport = "/dev/null"\nname = "hub"\n\n'
        '[[device]]\nfamily = "selspot"\nport = "/dev/null"\n\n'
        '[[device]]\nfamily = "timer"\nport = "/dev/null"\n\n'
    )
    for table, why in (
        ("[calibration]\nwand_length = 500\n", "calibration.frame_points: missing"),
        ('[calibration]\nwand_length = -1\nframe_points = "f.csv"\n', "positive length"),
        ('[calibration]\nwand_length = 500\nframe_points = "f.csv"\nwand_markers = [0]\n',
         "marker numbers"),
        ('[calibration]\nwand_length = 500\nframe_points = "f.csv"\nwand = 1\n', "unknown"),
    ):  # fmt: skip
        lab.write_text(devices + table)
        with pytest.raises(LabFileError, match=why):
            load_lab(lab)

    class Acq:  # what the wizard reads of the acquisition before it records
        def __init__(self, plan: Any) -> None:
            self.plan = plan

    def wizard(table: str) -> CalibrationWizard:
        lab.write_text(devices + table)
        return CalibrationWizard(Acq(plan_lab(lab, False, tmp_path)), None)  # type: ignore[arg-type]

    w = wizard("")
    assert w.devices() == ["hub", "selspot"]
    with pytest.raises(InputError, match="choose the device to calibrate: one of hub, selspot"):
        w.record("wand", "S", "s", 5, "timer")
    with pytest.raises(InputError, match=r"no \[calibration\] table"):
        w.record("wand", "S", "s", 5, "hub")
    w = wizard('[calibration]\nwand_length = 500\nframe_points = "f.csv"\n')
    cal = load_lab(lab).calibration
    assert cal is not None and cal.frame_points == tmp_path / "f.csv" and cal.wand_length == 500
    with pytest.raises(InputError, match="needs wand_markers and frame_markers"):
        w.record("wand", "S", "s", 5, "selspot")
    with pytest.raises(InputError, match=r"calibration\.frame_points: no file"):
        w.record("wand", "S", "s", 5, "hub")
    with pytest.raises(InputError, match="record the wand dance first"):
        w.record("lframe", "S", "s", 5)
