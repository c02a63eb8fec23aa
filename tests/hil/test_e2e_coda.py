"""A simulated CSX scanner recorded through a real pseudo-terminal, then read back.

``spotlab sim coda --pty`` serves the scanner (markers, rate, seed, truth);
``spotlab record --device coda=PORT`` records it; ``spotlab info`` decodes the
journal again; the replayed blocks put every unflagged record in its marker's
row, at the true position within the precision the scanner's angles give;
``spotlab reconstruct`` writes its trajectories (C3D) with the stored geometry.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
from _e2e import _first_line as first_line
from _e2e import run_cli, spawn_cli, stop_process

from spotlab.acquisition.replay import replay
from spotlab.console.cli import main
from spotlab.processing.decoding import decoder_for


@pytest.mark.timeout(60)
def test_record_info_and_replay_of_a_scanner(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    journal = tmp_path / "run.spj"
    truth = tmp_path / "coda.csv"
    out, err = tmp_path / "coda.stdout", tmp_path / "coda.stderr"
    sim = spawn_cli(
        ["sim", "coda", "--pty", "--markers", 6, "--seed", 4, "--truth", truth,
         "--lab", tmp_path / "lab"],
        out, err,
    )  # fmt: skip
    try:
        port = first_line(out, sim, err, timeout=30.0)
        result = run_cli(
            "record", "--device", f"coda={port},markers=6,base=1000", "--seconds", 2,
            "--out", journal, "--json", timeout=45,
        )  # fmt: skip
    finally:
        assert stop_process(sim) == 0
    assert result.returncode == 0, result.stderr
    stream = json.loads(result.stdout)["streams"][0]
    assert stream["name"] == "coda" and stream["lost_frames"] == 0

    # info and reconstruct in this process (their main; no interpreter start-up each).
    assert main(["info", str(journal), "--json"]) == 0
    assert "coda" in capsys.readouterr().out

    blocks = [b for name, b in replay(journal, decoder_for) if name == "coda"]
    data = np.concatenate([b.data for b in blocks])
    flags = np.concatenate([b.flags for b in blocks])
    seq = np.concatenate([b.seq for b in blocks])
    assert data.shape[1:] == (16, 1, 10) and len(seq) > 400  # 2 s at 300 Hz
    assert np.all(np.diff(seq) == 1)

    with open(truth, newline="") as fh:
        rows = {int(r["seq"]): r for r in csv.DictReader(fh) if r["sent"] == "1"}
    err_mm = []
    for k, s in enumerate(seq.tolist()):
        row = rows[s % 65536]
        for m in range(6):
            if flags[k, m, 0] & 0x01:  # 3-D valid, unflagged (it is in the marker's row)
                true = [float(row[f"led{m + 1}_{a}_mm"]) for a in "xyz"]
                err_mm.append(np.linalg.norm(data[k, m, 0, 1:4] - true))
    # The three crossings lie within the 2.7 ms sweep: the marker moves < 2 mm in it,
    # and the angle noise at 3 m gives a few mm in depth.
    assert len(err_mm) > 0.9 * 6 * len(seq)
    assert np.median(err_mm) < 5.0 and np.max(err_mm) < 30.0

    # Trajectories from the angles, with the unit's geometry stored in the recording.
    c3d = tmp_path / "run.c3d"
    assert main(["reconstruct", str(journal), "--out", str(c3d), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["base_mm"] == 1000.0 and summary["source"] == "angles"
    assert [m["label"] for m in summary["markers"]] == ["RO", "RY", "RG", "RC", "RB", "RV"]
    assert c3d.stat().st_size > 0
