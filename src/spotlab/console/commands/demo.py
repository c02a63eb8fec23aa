"""``spotlab demo``: the main job on the embedded default, with no hardware.

A simulated 4-camera × 32-LED lateral-photodiode system at 200 Hz is served on a
real pseudo-terminal with link faults injected; the SPX driver records it into a
crash-safe journal; the journal is decoded again and its counts are checked
against what the simulator says it injected. The recording is then reconstructed with
the simulator's true rig, exported as C3D and compared with the simulator's truth.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np

from spotlab.acquisition.recorder import Recorder
from spotlab.acquisition.replay import replay, summarize
from spotlab.acquisition.session import Session, SessionStatus
from spotlab.console.errors import CommandError
from spotlab.console.progress import Progress
from spotlab.drivers.selspot import SelspotDriver
from spotlab.hil.scoring import score_reconstruction
from spotlab.processing.decoding import decoder_for
from spotlab.processing.paths import check_output_dir
from spotlab.simulators import service

CAMERAS, LEDS, RATE_HZ = 4, 32, 200.0
# One of each link fault a serial line shows, at known times after START.
FAULTS = "bitflip@1.0,truncate@1.6,garbage@2.2,duplicate@2.8,drop@3.4,overflow@4.0:3,burst@4.6"
#: Largest RMS 3-D error (mm) of the reconstruction with the true rig that the verdict
#: accepts: the PSD noise of this scene gives about 2 mm (docs/simulators.md); a decoding,
#: timing or geometry bug gives tens of mm.
ACCURACY_RMS_MM = 3.0


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "demo",
        help="simulated system end to end: record with faults, decode, report",
        description="Serve a simulated 4-camera x 32-LED lateral-photodiode system at 200 Hz "
        "on a real pseudo-terminal with link faults injected, record it with the SPX driver, "
        "decode the recording again and check its counts against the simulator's fault log, "
        "then reconstruct it with the simulator's true rig and check the 3-D error against "
        "the simulator's truth.",
    )
    p.add_argument("--seconds", type=float, default=6.0, help="recording length (default 6)")
    p.add_argument(
        "--out",
        type=Path,
        default=Path("spotlab-demo"),
        help="output folder (default spotlab-demo; its demo files are replaced)",
    )
    p.add_argument("--seed", type=int, default=7, help="seed of the simulator (default 7)")
    p.add_argument("--json", action="store_true", help="print the report as one JSON object")
    p.set_defaults(run=run)


def _valid_fraction(journal: Path) -> float:
    valid = total = 0
    for _stream, block in replay(journal, decoder_for):
        ok = ~np.isnan(block.data[..., 0])
        valid += int(ok.sum())
        total += ok.size
    return valid / total if total else 0.0


def run(args: argparse.Namespace) -> int:
    if not args.seconds >= 1.0:
        raise CommandError("--seconds must be at least 1 for the demo")
    check_output_dir("--out", args.out)
    args.out.mkdir(parents=True, exist_ok=True)
    journal = args.out / "demo.spj"
    truth = args.out / "truth.csv"
    fault_log = args.out / "faults.json"
    rig, c3d = args.out / "rig.toml", args.out / "demo.c3d"
    for f in (journal, truth, fault_log, rig, c3d):
        f.unlink(missing_ok=True)
    options = service.SelspotSimOptions(
        cameras=CAMERAS,
        leds=LEDS,
        rate_hz=RATE_HZ,
        seed=args.seed,
        truth=truth,
        fault_log=fault_log,
        faults=FAULTS,
        motion="wand",
        rig_out=rig,
        # a dark floor (black cloth), as a lab lays out for PSD cameras: a reflecting
        # floor biases every reading by tens of mm (docs/simulators.md)
        floor_reflectance=0.0,
    )
    progress = Progress("recording", total=args.seconds)

    def show(status: SessionStatus) -> None:
        progress.update(status.elapsed_s, f"{sum(status.frames.values())} frames")

    server = service.serve_pty(options)
    try:
        driver = SelspotDriver(server.path, cameras=CAMERAS, leds=LEDS, rate_hz=RATE_HZ)
        recorder = Recorder(journal, {"command": "demo", "faults": FAULTS})
        session = Session([driver], [recorder], close_devices=True)
        session.run_for(args.seconds, progress=show)
        progress.close()
        port = server.path
    finally:
        server.stop()
    summary = summarize(journal, decoder_for).to_dict()
    stream = summary["streams"][0]
    injected = json.loads(fault_log.read_text())["totals"]
    corrupted = injected["corrupted_frames"]
    # Every frame damaged on the link is lost to the host; the device's own FIFO drops
    # are told apart by the frame number.
    link_lost = stream["lost_frames"] - stream["device_dropped"]
    reconstruction = score_reconstruction(journal, rig, truth, c3d)
    error_rms = reconstruction["error_rms_mm"]
    report: dict[str, Any] = {
        "system": f"{CAMERAS} cameras x {LEDS} LEDs at {RATE_HZ:g} Hz (simulated, real pty)",
        "port": str(port),
        "journal": str(journal),
        "journal_bytes": journal.stat().st_size,
        "frames_taken_by_device": injected["frames_taken"],
        "recording": stream,
        "injected": injected,
        "valid_sample_fraction": round(_valid_fraction(journal), 4),
        "reconstruction": reconstruction,
        "checks": {
            "every_damaged_frame_counted": link_lost == corrupted + injected["lost_frames"],
            "fifo_drops_counted": stream["device_dropped"] == injected["dropped_frames"],
            "duplicates_dropped": stream["duplicates"] == injected["duplicated_frames"],
            "no_valid_frame_lost": stream["frames"]
            == injected["frames_sent"] - corrupted - injected["lost_frames"],
            "accurate_reconstruction": error_rms is not None and error_rms <= ACCURACY_RMS_MM,
        },
    }
    if args.json:
        print(json.dumps(report))
        return 0
    print(f"spotlab demo: {report['system']}")
    print(f"  device port        {port}")
    print(f"  journal            {journal} ({report['journal_bytes'] / 1e3:.0f} kB)")
    print(
        f"  decoded again      {stream['frames']} frames in {stream['duration_s']:.2f} s "
        f"({stream['rate_hz']:.1f} Hz)"
    )
    print(
        f"  link faults        injected: {corrupted} frames damaged, "
        f"{injected['duplicated_frames']} duplicated, {injected['dropped_frames']} dropped "
        f"in the device FIFO"
    )
    print(
        f"                     counted:  {link_lost} lost on the link "
        f"({stream['crc_errors']} CRC errors, {stream['resyncs']} resyncs), "
        f"{stream['duplicates']} duplicates, {stream['device_dropped']} FIFO drops"
    )
    print(f"  valid samples      {100 * report['valid_sample_fraction']:.1f} % of LED x camera")
    rec = {
        k: "-" if v is None else f"{v:.2f}" if isinstance(v, float) else str(v)
        for k, v in report["reconstruction"].items()
    }
    print(
        f"  reconstructed      {rec['markers_reconstructed']} markers with the true rig, "
        f"RMS ray residual {rec['rms_ray_px']} counts, 3-D error RMS "
        f"{rec['error_rms_mm']} mm (max {rec['error_max_mm']} mm)"
    )
    print(" " * 21 + "(dark floor; a reflecting one biases PSD readings: docs/simulators.md)")
    print(f"  exported           {rec['c3d']}")
    failed = [name for name, ok in report["checks"].items() if not ok]
    verdict = not failed
    print(
        "  verdict            "
        + (
            "every fault detected and counted, no valid frame lost, 3-D error RMS "
            f"within {ACCURACY_RMS_MM:g} mm"
            if verdict
            else "MISMATCH: " + ", ".join(failed)
        )
    )
    print(f"  next               spotlab info {journal}")
    return 0 if verdict else 1
