"""Two SELSPOT systems and a timer recorded together, exported as 3-D trajectories on
the session time base (``spotlab export REC --c3d OUT --calibration RIG.toml``).

System A (+200 ppm) and system B (-150 ppm, its 4-camera ring turned 45 degrees) see the
same 32 markers of rigid clusters: both start the motion at one world time
(``--scene-epoch``). The calibration is their true rigs, A's cameras then B's. Each
exported instant is compared with the motion at the true instant of that session time
(one affine map session -> world time, fitted over both systems' frames), so what is
left is the detector noise, and no time bias: the error along each marker's velocity,
fitted as ``error = tau * velocity``, gives tau near 0 for every marker, while without
slot correction marker k lags by its slot time (k + 1/2) * 100 us.
"""

from __future__ import annotations

import json
import time
from contextlib import ExitStack
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pytest
from _e2e import _first_line as first_line
from _e2e import run_cli, spawn_cli
from test_e2e_sync import Lab, _procs, true_times

from spotlab.geometry import Camera, Rig
from spotlab.io import read_c3d, read_trc
from spotlab.simulators.motions import make_motion

RATE, LEDS, CAMERAS, SECONDS, SEED = 100, 32, 4, 6.0, 7
SLOT_S = 100e-6  # the SELSPOT driver's default slot
F64 = npt.NDArray[np.float64]


def run_lab(folder: Path, epoch_s: float) -> tuple[Lab, Path]:
    """Both systems and the timer recorded for SECONDS; the combined true rig (A then B)."""
    lab = folder / "lab"
    common = [
        "--cameras", CAMERAS, "--leds", LEDS, "--rate", RATE, "--lab", lab, "--seed", SEED,
        "--motion", "cluster", "--reflectance", 0, "--scene-epoch", repr(epoch_s),
    ]  # fmt: skip
    sims = {
        "a": ["sim", "selspot", "--pty", *common, "--lab-name", "sysA", "--clock-offset", 3.25,
              "--clock-drift-ppm", 200, "--rig-out", folder / "rig-a.toml"],
        "b": ["sim", "selspot", "--pty", *common, "--lab-name", "sysB", "--clock-offset", 41.5,
              "--clock-drift-ppm", -150, "--ring-phase", 45, "--rig-out", folder / "rig-b.toml"],
        "t": ["sim", "timer", "--pty", "--rate", RATE, "--input", "0=sysA", "--input", "1=sysB",
              "--lab", lab, "--seed", 3, "--clock-offset", 1000, "--clock-drift-ppm", 30],
    }  # fmt: skip
    truth = {k: folder / f"{k}-truth.csv" for k in sims}
    journal = folder / "rec.spj"
    with ExitStack() as stack:
        procs = stack.enter_context(_procs())
        outs = {}
        for key, args in sims.items():
            out, err = folder / f"{key}.stdout", folder / f"{key}.stderr"
            procs.append(spawn_cli([*args, "--truth", truth[key]], out, err))
            outs[key] = (out, procs[-1], err)
        ports = {k: first_line(*v, timeout=30.0) for k, v in outs.items()}
        devices = [f"timer={ports['t']}", f"selspot={ports['a']}", f"selspot={ports['b']}"]
        result = run_cli(
            "record", *[x for d in devices for x in ("--device", d)], "--cameras", CAMERAS,
            "--leds", LEDS, "--rate", RATE, "--seconds", SECONDS, "--out", journal, "--json",
            timeout=SECONDS + 60,
        )  # fmt: skip
    assert result.returncode == 0, result.stderr
    names = {"t": "timer", "a": "selspot0", "b": "selspot1"}
    rig = folder / "rig.toml"
    cams = [
        Camera(c.K, c.dist, c.R, c.t, c.size, f"{system}_{c.name}")
        for system in ("a", "b")
        for c in Rig.load(folder / f"rig-{system}.toml")
    ]
    Rig(cams).save(rig)
    return Lab(journal, {names[k]: v for k, v in truth.items()}, result), rig


def export(lab: Lab, rig: Path, folder: Path, name: str, *extra: str) -> tuple[dict, Path]:
    ts, c3d = folder / f"{name}.csv", folder / f"{name}.c3d"
    result = run_cli(
        "export", lab.journal, "--calibration", rig, "--c3d", c3d, "--trc", c3d.with_suffix(".trc"),
        "--timestamps", ts, "--wiring", "selspot0=0", "--wiring", "selspot1=1", "--json", *extra,
        timeout=60,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert "Traceback" not in result.stderr
    return json.loads(result.stdout), c3d


def world_of_session(lab: Lab, timestamps: Path) -> tuple[float, float]:
    """(alpha, beta) of world = alpha * session + beta, over both systems' edge frames."""
    import csv

    rows: dict[str, list[dict[str, str]]] = {}
    with open(timestamps, newline="") as fh:
        for row in csv.DictReader(fh):
            rows.setdefault(row["stream"], []).append(row)
    s_all, w_all = [], []
    for name in ("selspot0", "selspot1"):
        sel = [r for r in rows[name] if r["method"] == "edge"]
        w = true_times(lab, name, sel)
        s = np.array([float(r["time_s"]) for r in sel])
        ok = np.isfinite(w)
        assert ok.sum() > 0.9 * len(sel)
        s_all.append(s[ok])
        w_all.append(w[ok])
    s, w = np.concatenate(s_all), np.concatenate(w_all)
    alpha, beta = np.polyfit(s, w - w[0], 1)
    res = w - w[0] - (alpha * s + beta)
    assert np.max(np.abs(res)) < 50e-6  # one affine map: the session time base holds
    return float(alpha), float(beta + w[0])


def time_lag(err: F64, vel: F64, moving: npt.NDArray[np.bool_]) -> F64:
    """Per marker, tau (s) of the least-squares fit err = tau * velocity over samples."""
    e = np.where(moving[..., None], err, 0.0)
    v = np.where(moving[..., None], vel, 0.0)
    return np.asarray(np.nansum(e * v, axis=(0, 2)) / np.nansum(v * v, axis=(0, 2)))


@pytest.mark.timeout(90)
def test_two_systems_exported_on_session_time_match_the_truth_without_slot_skew(
    tmp_path: Path,
) -> None:
    epoch = time.monotonic()
    lab, rig = run_lab(tmp_path, epoch)
    summary, c3d = export(lab, rig, tmp_path, "sync")
    assert summary["cameras"] == 2 * CAMERAS and summary["markers"] == LEDS
    assert summary["rate_hz"] == RATE and summary["session_reference"] == "timer"
    assert summary["streams"]["selspot0"]["cameras"] == CAMERAS
    alpha, beta = world_of_session(lab, tmp_path / "sync.csv")

    trial = read_c3d(c3d)
    session = (trial.first_frame - 1 + np.arange(trial.n_frames)) / trial.point_rate
    assert trial.n_frames > 0.8 * SECONDS * RATE
    assert abs(session[0] - summary["session_start_s"]) < 1e-9
    trc = read_trc(c3d.with_suffix(".trc"))  # the TRC's Time column is the session time
    assert np.allclose(trc.metadata["times"], session, atol=1e-6)

    motion = make_motion("cluster", LEDS, SEED)
    scene_t = alpha * session + beta - epoch
    ids = np.arange(LEDS)

    def truth_at(t: F64) -> F64:
        return np.stack([motion.sample(t, np.full(t.size, k)) for k in ids], axis=1)

    true = truth_at(scene_t)
    vel = (truth_at(scene_t + 1e-4) - truth_at(scene_t - 1e-4)) / 2e-4  # mm/s
    moving = np.linalg.norm(vel, axis=-1) > 300.0

    err = trial.points - true
    dist = np.linalg.norm(err, axis=-1)
    seen = np.isfinite(dist)
    assert seen.mean() > 0.8, seen.mean()
    rms = float(np.sqrt(np.mean(dist[seen] ** 2)))
    tau = time_lag(err, vel, moving & seen)
    bad = np.argwhere(dist > 10.0)
    print(f"sync export: rms {rms:.3f} mm, p99 {np.percentile(dist[seen], 99):.3f} mm, "
          f"max {np.max(dist[seen]):.3f} mm, tau {tau.min() * 1e6:+.0f}..{tau.max() * 1e6:+.0f}"
          f" us, mean {tau.mean() * 1e6:+.0f} us; > 10 mm at (instant, marker) "
          f"{bad[:10].tolist()}")  # fmt: skip
    # Measured: 1.16-1.26 mm RMS, p99 2.3-2.5 mm (PSD noise, 8 cameras); tau within
    # +-0.22 ms per marker, mean within 0.03 ms.
    assert rms < 3.0 and np.percentile(dist[seen], 99) < 6.0
    assert abs(tau.mean()) < 100e-6 and np.max(np.abs(tau)) < 400e-6

    # the same recording without slot correction: marker k leads by its slot time; the
    # readings are the same, so the difference of the fitted lags is the slot time alone
    summary_n, c3d_n = export(lab, rig, tmp_path, "noslot", "--no-slot-correction")
    assert summary_n["slot_correction"] is False
    trial_n = read_c3d(c3d_n)
    lo = max(trial.first_frame, trial_n.first_frame)
    hi = min(trial.first_frame + trial.n_frames, trial_n.first_frame + trial_n.n_frames)
    rows, rows_n = np.arange(lo, hi) - trial.first_frame, np.arange(lo, hi) - trial_n.first_frame
    err_n = trial_n.points[rows_n] - true[rows]
    both = moving[rows] & np.isfinite(err_n[..., 0]) & seen[rows]
    shift = time_lag(err_n, vel[rows], both) - time_lag(err[rows], vel[rows], both)
    slot = (ids + 0.5) * SLOT_S
    print(f"no slot correction: lag - slot time {np.max(np.abs(shift - slot)) * 1e6:.1f} us, "
          f"last markers {shift[-4:].mean() * 1e3:.3f} ms")  # fmt: skip
    assert np.max(np.abs(shift - slot)) < 50e-6
    assert shift[-4:].mean() > 2.5e-3  # the last markers of the table: ~3 ms
