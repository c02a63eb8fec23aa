"""Two simulated CSX scanners and a timer, recorded together through real pseudo-terminals.

The three simulators are served on real ptys by threads of the test (``spotlab record``
is its own process); the scanners publish their scan pulses to a shared lab folder, the
timer's inputs 0 and 1 are wired to them. Every recorded scan of each scanner must have exactly one
timer edge, at the scan's true start as read by the timer's own clock, and each scan's
session time must be its true instant on the timer's clock within 50 µs (issue 18:
synchronisation with the timer family; TARGETS.md). Unit B stands 800 mm aside, turned 15
degrees. ``spotlab reconstruct`` carries B into A's frame by the markers both see and
puts B's markers, on session time, at A's instants; only then, at the end, are the
markers scored against the simulators' truth: their errors, whitened by the precision
model's prediction (depth error growing as the square of range, for the unit's angle
noise), must have unit spread. Entry 12 of the table shares entry 0's flash slot
(aliasing) and the units misread colours: such records are flagged, never reported
under a marker's ID, and agree one for one with the simulators' fault logs.

The default run records 2 s; ``long`` (``make long``) records ``SPOTLAB_CODA_SECONDS``
(4 by default; issue 18 asks for 60).
"""

from __future__ import annotations

import csv
import json
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from _e2e import run_cli

from spotlab.acquisition.timebase import session_timebase
from spotlab.console.cli import main
from spotlab.core.frames import FrameBlock
from spotlab.drivers.timer import extract_edges
from spotlab.io import read_c3d
from spotlab.processing.scanner_trajectories import COUNT_RAD
from spotlab.processing.session_times import (
    DecodedStreams,
    decode_streams,
    read_streams,
    recorded_wiring,
)
from spotlab.reconstruction.scanner import scanner_precision
from spotlab.simulators import coda_scene as scene
from spotlab.simulators.coda_service import CodaSimOptions, serve_coda_pty
from spotlab.simulators.service import TimerSimOptions, serve_timer_pty
from spotlab.simulators.transports.pty import PtyServer

#: Moving markers RO RY RG RC (IDs 1-4; RB, ID 5, moves too), the static L-frame
#: (IDs 50-53), four codes not in the scene, and RB as entry 12: at 300 Hz a unit serves
#: 12 flash slots, so RB shares RO's slot and both are reported aliased. Recorded in RAW
#: mode (angles and crossing times; 266-byte frames, 0.8 Mbit/s a unit).
CODES = ("RO", "RY", "RG", "RC", "WR", "WO", "WY", "WG", "OR", "OY", "OG", "OC", "RB")
IDS = (1, 2, 3, 4, 50, 51, 52, 53, 8, 9, 10, 11, 5)
ALIASED = ("RO", "RB")
SCORED = ("RY", "RG", "RC", "WR", "WO", "WY", "WG")
UNITS = (("codaA", 3, 150, scene.Pose()), ("codaB", 11, -80, scene.Pose(15.0, (800.0, 0.0, 0.0))))
RATE = 300.0
SHORT_S = 2.0
#: Recording length of the long run; issue 18 asks for 60 s (``SPOTLAB_CODA_SECONDS=60``).
LONG_S = float(os.environ.get("SPOTLAB_CODA_SECONDS", "4"))
F_COLOUR, F_ALIASED, F_GHOST = 0x10, 0x20, 0x40


@dataclass
class Run:
    """What one recording left: the journal, the truths and fault logs, the CLI's output,
    and the journal's blocks decoded once (by stream)."""

    journal: Path
    truth: dict[str, Path]
    logs: dict[str, Path]
    timer_truth: Path
    record: dict[str, Any]
    decoded: DecodedStreams

    @property
    def blocks(self) -> dict[str, list[FrameBlock]]:
        return self.decoded.blocks


def _rows(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def _record(tmp_path: Path, seconds: float) -> Run:
    """Two scanners and a timer, each served on a real pty by a thread of this process
    (no interpreter start-up each), recorded by ``spotlab record`` for ``seconds``."""
    lab = tmp_path / "lab"
    lab.mkdir()
    journal = tmp_path / "run.spj"
    truth = {n: tmp_path / f"{n}.npz" for n, *_ in UNITS}
    logs = {n: tmp_path / f"{n}.faults.json" for n, *_ in UNITS}
    timer_truth = tmp_path / "timer.csv"
    servers: list[PtyServer] = []
    try:
        for k, (name, offset, drift, pose) in enumerate(UNITS):
            where = f"{pose.yaw_deg:g},{','.join(f'{v:g}' for v in pose.origin)}"
            options = CodaSimOptions(
                markers=5, seed=k + 1, truth=truth[name], fault_log=logs[name], lab=lab,
                lab_name=name, clock_offset_s=offset, clock_drift_ppm=drift, pose=where,
                reference=1,
            )  # fmt: skip
            servers.append(serve_coda_pty(options))
        timer = TimerSimOptions(
            rate_hz=100.0, inputs="0=codaA,1=codaB", lab=lab, truth=timer_truth,
            clock_offset_s=1000.0,
        )  # fmt: skip
        servers.append(serve_timer_pty(timer))
        ports = [str(server.path) for server in servers]
        table = "+".join(CODES)
        result = run_cli(
            "record", "--device", f"timer={ports[2]}",
            "--device", f"coda={ports[0]},name=codaA,markers={table},out=RAW",
            "--device", f"coda={ports[1]},name=codaB,markers={table},out=RAW",
            "--wiring", "codaA=0", "--wiring", "codaB=1",
            "--seconds", seconds, "--out", journal, "--json", timeout=90 + 2 * seconds,
        )  # fmt: skip
    finally:
        for server in servers:
            server.stop()
    assert result.returncode == 0, result.stderr
    decoded = decode_streams(journal)
    return Run(journal, truth, logs, timer_truth, json.loads(result.stdout), decoded)


def _check_sync(run: Run, seconds: float, listened_part: float) -> None:
    """Every frame kept; every scan one timer edge within 1 µs of its true start.

    ``listened_part``: the part of the nominal scans that must be recorded and of those
    within the timer's span (a short run on a loaded machine starts its devices
    further apart, relatively)."""
    streams = {s["name"]: s for s in run.record["streams"]}
    assert all(streams[n]["lost_frames"] == 0 for n in ("timer", "codaA", "codaB")), streams
    rows = _rows(run.timer_truth)
    t_true = np.array([float(r["true_time_s"]) for r in rows])
    counter = np.array([10 * int(r["device_us"]) for r in rows], dtype=np.float64)
    slope, icept = np.polyfit(t_true - t_true[0], counter, 1)
    timer_edges = extract_edges(run.blocks["timer"])
    for channel, (name, *_) in enumerate(UNITS):
        seqs = np.concatenate([b.seq for b in run.blocks[name]])
        assert len(seqs) > min(0.8, listened_part) * RATE * seconds and np.all(np.diff(seqs) == 1)
        edges = timer_edges.select(channel)
        frame_true = _scan_starts(run.truth[name], seqs)
        edge_true = (edges.tick - icept) / slope + t_true[0]
        span = (edges.frame_ticks[[0, -1]] - icept) / slope + t_true[0]
        listened = (frame_true > span[0]) & (frame_true <= span[1])
        assert listened.sum() > listened_part * len(seqs)
        frame_true = frame_true[listened]
        nearest = np.clip(np.searchsorted(edge_true, frame_true), 1, len(edge_true) - 1)
        err_s = np.minimum(
            np.abs(edge_true[nearest - 1] - frame_true), np.abs(edge_true[nearest] - frame_true)
        )
        assert err_s.max() < 1e-6, err_s.max()
        inside = (edge_true >= frame_true[0] - 1e-6) & (edge_true <= frame_true[-1] + 1e-6)
        assert int(inside.sum()) == len(frame_true)


def _sent(truth: Path) -> tuple[dict[int, float], dict[int, int]]:
    """Scan start (world s) and frame_no of every frame a unit sent, by seq."""
    t = np.load(truth)
    sent = t["sent"]
    seq, start, frame_no = t["seq"][sent], t["time_s"][sent], t["frame_no"][sent]
    return dict(zip(seq.tolist(), start.tolist(), strict=True)), dict(
        zip(seq.tolist(), frame_no.tolist(), strict=True)
    )


def _scan_starts(truth: Path, seqs: np.ndarray) -> np.ndarray:
    start, _ = _sent(truth)
    return np.array([start[int(s) % 65536] for s in seqs])


def _check_identities(run: Run) -> dict[str, int]:
    """Aliased and misread records flagged, in the extra rows, one for one with the logs."""
    counted = {"colour": 0, "ghost": 0, "alias": 0}
    for name, *_ in UNITS:
        blocks = run.blocks[name]
        data = np.concatenate([b.data[:, :, 0] for b in blocks])
        flags = np.concatenate([b.flags[:, :, 0] for b in blocks]).astype(np.int64)
        seqs = np.concatenate([b.seq for b in blocks])
        m = len(CODES)
        for code in ALIASED:  # never in their rows
            assert not (flags[:, CODES.index(code)] & 0x7F).any()
        assert not (flags[:, :m] & (F_COLOUR | F_ALIASED | F_GHOST)).any()
        extra_ids, extra_flags = data[:, m:, 0], flags[:, m:]
        aliased = (extra_flags & F_ALIASED) != 0
        assert np.all(extra_ids[aliased] == 1)  # both reported as entry 0's ID
        assert aliased.sum(axis=1).max() == 2 and aliased.sum() > 1.5 * len(seqs)
        log = json.loads(run.logs[name].read_text())
        _, frame_no = _sent(run.truth[name])
        got = {frame_no[int(s) % 65536] for s in seqs}
        for kind, bit in (("colour", F_COLOUR), ("ghost", F_GHOST)):
            logged = [e for e in log["faults"] if e["kind"] == kind and e["frame_no"][0] in got]
            assert int(((extra_flags & bit) != 0).sum()) == len(logged), (name, kind)
            counted[kind] += len(logged)
        alias = {e["detail"]["marker"]: e for e in log["faults"] if e["kind"] == "alias"}
        assert sorted(alias) == [1, 5] and all(e["detail"]["reported"] == 1 for e in alias.values())
        counted["alias"] += sum(e["detail"]["scans"] for e in alias.values())
    return counted


def _mid_sweeps(timing: Any) -> np.ndarray:
    """Session time of each scan's mid-sweep on the stream's frame grid (NaN: lost)."""
    k = timing.seq - timing.seq[0]
    out = np.full(int(k[-1]) + 1, np.nan)
    out[k] = timing.time_s + 0.4 / RATE
    return out


def _sigma_rad(p_unit: np.ndarray) -> np.ndarray:
    """The simulated unit's angle noise (rad) at its points: its noise at the range plus
    the quantisation of a count (scoring only: the simulator's model)."""
    r = np.linalg.norm(p_unit, axis=-1)
    return COUNT_RAD * np.sqrt(scene.angle_sigma_counts(r, 0.0) ** 2 + 1 / 12)


def _whitened(
    err_world: np.ndarray, truth_world: np.ndarray, pose: scene.Pose, factor: np.ndarray
) -> np.ndarray:
    """Errors (N, 3) in the unit's axes over the precision model's sd (times ``factor``)."""
    p_unit = pose.to_unit(truth_world)
    sd = scanner_precision(p_unit, 1.0, 1000.0)[0] * _sigma_rad(p_unit)[..., None]
    return (err_world @ pose.rotation) / (sd * factor[..., None])


def _score(run: Run, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> dict[str, Any]:
    """Reconstruct through the command line, then score against the truth (the end)."""
    c3d = tmp_path / "run.c3d"
    assert main(["reconstruct", str(run.journal), "--out", str(c3d), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    trial = read_c3d(c3d)
    fit = summary["units"][1]["alignment"]
    # A's scans: the world instant of each mid-sweep, from A's truth.
    devices, timer, _ = read_streams(run.journal, run.decoded)  # decoded once
    base = session_timebase(devices, timer, recorded_wiring(run.journal))
    seqs = base.streams["codaA"].seq
    start = np.full(trial.n_frames, np.nan)
    start[seqs - seqs[0]] = _scan_starts(run.truth["codaA"], seqs)
    at_world = start + 0.4 / RATE
    # B's interpolation weights at A's instants: the model's sd shrinks by
    # sqrt((1-w)^2 + w^2) for a mean of two scans.
    t_a, t_b = (_mid_sweeps(base.streams[n]) for n in ("codaA", "codaB"))
    ok_b = np.isfinite(t_b)
    i = np.clip(np.searchsorted(t_b[ok_b], t_a), 1, ok_b.sum() - 1)
    w = (t_a - t_b[ok_b][i - 1]) / (t_b[ok_b][i] - t_b[ok_b][i - 1])
    factors = {"codaA": np.ones_like(w), "codaB": np.sqrt((1 - w) ** 2 + w**2)}
    out: dict[str, Any] = {"alignment_rms_mm": fit["rms_mm"], "pairs": fit["pairs"]}
    out["sync_us"] = _session_errors_us(run, base)
    worst = 0.0
    for name, _, _, pose in UNITS:
        zs, errs = [], []
        for code in SCORED:
            col = trial.labels.index(f"{name}.{code}")
            truth = scene.marker_positions(np.array([IDS[CODES.index(code)]]), at_world[:, None])
            err = trial.points[:, col] - truth[:, 0]
            ok = np.isfinite(err).all(axis=1)
            zs.append(_whitened(err[ok], truth[ok, 0], pose, factors[name][ok]))
            errs.append(np.linalg.norm(err[ok], axis=1))
        z = np.concatenate(zs)
        worst = max(worst, float(np.abs(z).max()))
        out[name] = {
            "samples": int(z.shape[0]),
            "rms_z_xyz": np.sqrt(np.mean(z**2, axis=0)).round(4).tolist(),
            "rms_z": round(float(np.sqrt(np.mean(z**2))), 4),
            "mean_z_xyz": z.mean(axis=0).round(4).tolist(),
            "error_mm_median": round(float(np.median(np.concatenate(errs))), 4),
            "error_mm_max": round(float(np.concatenate(errs).max()), 4),
        }
    out["max_abs_z"] = round(worst, 2)
    return out


def _session_errors_us(run: Run, base: Any) -> dict[str, float]:
    """Largest error (µs) of each unit's session times of its edge-timed scans against
    their true instants on the timer's session clock (the timer's frames give the world
    time of session time 0)."""
    timer = {int(r["seq"]): float(r["true_time_s"]) for r in _rows(run.timer_truth)
             if r["sent"] == "1"}  # fmt: skip
    ts = base.streams["timer"]
    zero = np.median(np.array([timer[int(q) % 65536] for q in ts.seq]) - ts.time_s)
    out = {}
    for name, *_ in UNITS:
        s = base.streams[name]
        edge = s.method == "edge"
        world = _scan_starts(run.truth[name], s.seq[edge])
        out[name] = round(float(np.max(np.abs(world - zero - s.time_s[edge]))) * 1e6, 2)
    return out


def _run_and_score(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], seconds: float, listened_part: float
) -> dict[str, Any]:
    t0 = time.monotonic()
    run = _record(tmp_path, seconds)
    t1 = time.monotonic()
    _check_sync(run, seconds, listened_part)
    figures = _score(run, tmp_path, capsys)
    figures["flagged"] = _check_identities(run)
    figures["seconds"] = {"record": round(t1 - t0, 1), "score": round(time.monotonic() - t1, 1)}
    with capsys.disabled():
        print(f"\n{seconds:g} s:", json.dumps(figures))
    return figures


@pytest.mark.timeout(120)
def test_two_scanners_and_a_timer_in_one_frame_and_time(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    f = _run_and_score(tmp_path, capsys, SHORT_S, 0.5)
    # Measured in six runs (2 s, 2026-11-25, load 8-10 on 2 cores): alignment RMS
    # 0.006-0.010 mm; session times within 0.1 µs; RMS of the whitened errors 1.002-1.017
    # per unit (4 000-5 000 samples each: 1 % is one standard error); largest |z|
    # 4.0-4.3; 15-17 colour-ambiguous, 8 ghost and 2 700-3 100 aliased records, as the
    # fault logs say.
    assert f["alignment_rms_mm"] < 0.05
    for name, *_ in UNITS:
        assert f[name]["samples"] > 0.8 * len(SCORED) * RATE * SHORT_S
        assert abs(f[name]["rms_z"] - 1.0) < 0.04, f[name]
    assert f["max_abs_z"] < 6.0
    assert max(f["sync_us"].values()) < 50.0  # TARGETS.md: within 50 µs of the truth
    assert f["flagged"]["colour"] > 0 and f["flagged"]["ghost"] > 0
    assert f["flagged"]["alias"] > 0.8 * RATE * SHORT_S


@pytest.mark.long
@pytest.mark.timeout(120 + 2 * LONG_S)
def test_two_scanners_and_a_timer_long(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    f = _run_and_score(tmp_path, capsys, LONG_S, 0.8)
    assert f["alignment_rms_mm"] < 0.5
    for name, *_ in UNITS:
        assert abs(f[name]["rms_z"] - 1.0) < 0.02, f[name]  # issue 18: within 2 %
    assert f["max_abs_z"] < 7.0
    assert max(f["sync_us"].values()) < 50.0
