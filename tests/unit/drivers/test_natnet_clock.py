"""A NatNet stream's device time is the server's clock: the session clock model fits it.

The simulated Motive's clock runs ``--clock-drift-ppm`` fast or slow and starts at
``--clock-offset`` s; a frame's mid-exposure stamp is that clock. The recording's ticks
must be exactly those stamps (10 MHz ticks), and the session clock model
(:func:`spotlab.acquisition.timebase.session_timebase`) must recover the drift:

* within 1 ppm from the instants the server's clock reached each frame (on this
  host's clock, as the simulator scheduled them): the model, given clean host times.
  The arrivals model converges over seconds (on clean times it is 4.6 ppm short of
  +250 ppm after 8 s, 0.6 ppm after 16 s), so the recording lasts 16 s;
* within 20 ppm from the recording's own arrival stamps on a loaded CI host (the
  loopback delivery scatters by up to milliseconds and the envelope by 100 us: a
  recording of minutes pins it to a ppm).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from spotlab.acquisition.recorded_frames import DeviceFrames
from spotlab.acquisition.timebase import session_timebase
from spotlab.console.cli import main
from spotlab.processing.session_times import read_streams
from spotlab.simulators.natnet import CLOCK_HZ, NatNetServer
from spotlab.simulators.natnet_scene import NatNetScene

RATE = 120.0


def test_the_recorded_ticks_are_the_servers_own_stamps(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out, truth = tmp_path / "r.spj", tmp_path / "t.npz"
    scene = NatNetScene(markers=6, cameras=2, rate_hz=RATE, seed=0)
    with NatNetServer(scene, truth=truth, clock_drift_ppm=250.0, clock_offset_s=1234.5) as srv:
        code = main(["record", "--device", f"natnet={srv.address}", "--seconds", "2",
                     "--out", str(out)])  # fmt: skip
    assert code == 0, capsys.readouterr().err
    (dev,), _, _ = read_streams(out)
    t = np.load(truth)
    row = {int(k): i for i, k in enumerate(t["frame"])}
    np.testing.assert_array_equal(dev.ticks, t["ticks"][[row[int(k)] for k in dev.seq]])
    np.testing.assert_array_equal(dev.ticks, np.round((1234.5 + dev.seq / RATE) * CLOCK_HZ))


# 16 s of recording: the drift needs them (make long; the ticks are checked above).
@pytest.mark.long
def test_the_clock_model_recovers_the_servers_drift(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    ppm = 250.0
    out, truth, report = tmp_path / "r.spj", tmp_path / "t.npz", tmp_path / "sync.json"
    scene = NatNetScene(markers=6, cameras=2, rate_hz=RATE, seed=0)
    with NatNetServer(scene, truth=truth, clock_drift_ppm=ppm, clock_offset_s=1234.5) as srv:
        code = main(["record", "--device", f"natnet={srv.address}", "--seconds", "16",
                     "--out", str(out)])  # fmt: skip
    assert code == 0, capsys.readouterr().err
    (dev,), timer, _ = read_streams(out)
    assert timer is None and dev.spec.tick_hz == CLOCK_HZ and dev.spec.rate_hz == RATE
    t = np.load(truth)
    row = {int(k): i for i, k in enumerate(t["frame"])}
    rows = np.array([row[int(k)] for k in dev.seq])
    np.testing.assert_array_equal(dev.ticks, t["ticks"][rows])  # the server's own stamps
    np.testing.assert_array_equal(dev.ticks, np.round((1234.5 + dev.seq / RATE) * CLOCK_HZ))

    clean = DeviceFrames(dev.name, dev.seq, dev.ticks, t["due_ns"][rows], dev.spec)
    (fitted,) = session_timebase([clean], None).report()["streams"]
    assert abs(fitted["drift_ppm"] - ppm) < 1.0, fitted

    capsys.readouterr()
    assert main(["export", str(out), "--sync-report", str(report)]) == 0
    (live,) = json.loads(report.read_text())["streams"]
    assert live["method"] == "arrivals"
    assert abs(live["drift_ppm"] - ppm) < 20.0, live


def test_sim_natnet_refuses_an_impossible_drift(capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["sim", "natnet", "--clock-drift-ppm", "5000", "--seconds", "0.1"])
    assert code != 0
    assert "clock drift must be within +-1000 ppm" in capsys.readouterr().err
