"""``spotlab sim FAMILY``: run a simulated device on a pseudo-terminal or TCP port."""

from __future__ import annotations

import argparse
import signal
import sys
import threading
from pathlib import Path
from typing import TYPE_CHECKING, Any

from spotlab.console.commands import sim_natnet, sim_wsx
from spotlab.console.commands.sim_qualisys import add_qualisys_arguments, run_qualisys
from spotlab.console.errors import CommandError
from spotlab.io import FileFormatError
from spotlab.processing.paths import check_output_dir, check_output_paths
from spotlab.reconstruction.identification import MarkerModel
from spotlab.simulators import service
from spotlab.simulators.centroid_service import (
    CENTROID_MOTIONS,
    LFRAME_MARKERS,
    CentroidSimOptions,
    serve_centroid_pty,
)
from spotlab.simulators.centroid_truth_model import model_walk
from spotlab.simulators.coda_service import CodaSimOptions, serve_coda_pty, serve_coda_tcp
from spotlab.simulators.faults import parse_schedule
from spotlab.simulators.lab import lab_dir
from spotlab.simulators.motions import MOTIONS, from_c3d, make_motion, static_points

if TYPE_CHECKING:
    from spotlab.simulators.transports.pty import PtyServer
    from spotlab.simulators.transports.tcp import TcpServer


class _RateAction(argparse.Action):
    """``--rate``, noting that it was given (families differ in their default rate)."""

    def __call__(
        self,
        parser: argparse.ArgumentParser,
        namespace: argparse.Namespace,
        values: Any,
        option_string: str | None = None,
    ) -> None:
        setattr(namespace, self.dest, values)
        namespace.rate_given = True


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "sim",
        help="run a simulated device (pseudo-terminal or TCP) until stopped",
        description="Run a byte-level device simulator. With --pty the first line of stdout is "
        "the device path to open; with --tcp it is a socket:// URL. It serves until stopped "
        "(Ctrl-C, SIGTERM) or until --seconds have passed.",
    )
    p.add_argument(
        "family",
        choices=["selspot", "timer", "centroid", "coda", "qualisys", "natnet", "wsx"],
        help="device family",
    )
    where = p.add_mutually_exclusive_group()
    where.add_argument(
        "--pty", action="store_true", help="serve on a real pseudo-terminal (default)"
    )
    where.add_argument(
        "--tcp",
        nargs="?",
        const=0,
        type=int,
        metavar="PORT",
        help="serve on 127.0.0.1:PORT (0 or omitted: any free port)",
    )
    p.add_argument(
        "--cameras",
        type=int,
        default=None,
        help="cameras: selspot 1-4 (default 2), centroid 1-16 (default 8)",
    )
    p.add_argument("--leds", type=int, default=8, help="LEDs, 1-128 (default 8)")
    p.add_argument(
        "--rate",
        type=float,
        default=100.0,
        action=_RateAction,
        help="frame rate the scene is built for, Hz (default 100; coda: scan rate, default 300)",
    )
    p.add_argument("--seed", type=int, default=0, help="seed of noise, motion and random faults")
    p.add_argument(
        "--truth",
        type=Path,
        help="write ground truth CSV (seq, true_time_s, markers); coda: .npz arrays for that "
        "suffix",
    )
    p.add_argument("--faults", default="", help="fault schedule, e.g. 'bitflip@1.5,drop@2,reset@6'")
    p.add_argument("--fault-log", type=Path, help="write what was injected as JSON")
    p.add_argument(
        "--clock-offset",
        type=float,
        default=0.0,
        metavar="SECONDS",
        help="the device counter reads this many seconds at power-up (default 0)",
    )
    p.add_argument(
        "--clock-drift-ppm",
        type=float,
        default=0.0,
        metavar="PPM",
        help="the device oscillator's error in parts per million, positive runs fast (default 0)",
    )
    p.add_argument(
        "--clock-jitter",
        type=float,
        default=0.0,
        metavar="SECONDS",
        help="RMS scatter (s) of the instant a frame is taken around the time its timestamp "
        "names (default 0)",
    )
    p.add_argument(
        "--clock-step",
        action="append",
        default=[],
        metavar="AT:DELTA",
        help="the device counter jumps by DELTA s at AT s after power-up (frame pulses do not "
        "move); repeat for several",
    )
    p.add_argument(
        "--motion",
        default=None,
        help="selspot: wand (default), cluster, gait, lframe (static L-frame), or a C3D file "
        "whose markers move the LEDs; centroid: walk (default, the 40-marker body), static "
        "(the body standing still, swaying a few mm), rom (range of motion: every joint "
        "moves while the subject turns on the spot), wand (a passive wand of --markers 2 or "
        "3 waved through the volume) or lframe (a static L-frame on the floor)",
    )
    p.add_argument(
        "--reflectance",
        type=float,
        default=0.05,
        help="floor reflectance, 0-1 (default 0.05; 0: no floor reflection)",
    )
    p.add_argument(
        "--rig-out",
        type=Path,
        metavar="RIG.toml",
        help="write the simulated cameras' true calibration (spotlab rig TOML, detector counts)",
    )
    p.add_argument(
        "--frame-points-out",
        type=Path,
        metavar="POINTS.csv",
        help="write the reference object's published coordinates (mm) as CSV, the "
        "--frame-points table of spotlab calibrate: selspot: the motion's static markers "
        "(the L-frame first), columns marker (LED number, 1-based), X, Y, Z; centroid: the "
        "L-frame's markers, columns X, Y, Z",
    )
    p.add_argument(
        "--ring-phase",
        type=float,
        default=0.0,
        metavar="DEG",
        help="selspot: turn the camera ring about the vertical by DEG degrees (a second "
        "system's cameras elsewhere around the same volume)",
    )
    p.add_argument(
        "--scene-epoch",
        type=float,
        metavar="WORLD_S",
        help="selspot: the motion starts at this monotonic clock time (s) instead of at "
        "power-up; systems given the same epoch see the same markers",
    )
    p.add_argument(
        "--lab",
        type=Path,
        metavar="DIR",
        help="lab folder where simulators publish their frame pulses (default: $SPOTLAB_LAB, "
        "else spotlab-lab-<uid> in the temp folder)",
    )
    p.add_argument(
        "--lab-name",
        default=None,
        help="selspot: name under which its frame pulses are published (default 'selspot'; "
        "give each system its own)",
    )
    p.add_argument(
        "--input",
        action="append",
        default=[],
        metavar="N=SOURCE",
        help="timer: wire input N (0-7) to the frame pulses of the lab device SOURCE; repeat",
    )
    csx = p.add_argument_group("coda (optomechanical scanner)")
    csx.add_argument(
        "--pose", default="", metavar="YAW,X,Y,Z",
        help="coda: the unit turned YAW degrees about the vertical at X,Y,Z mm of the world",
    )  # fmt: skip
    csx.add_argument(
        "--reference", action="store_true",
        help="coda: a static L-frame (markers WR, WO, WY, WG) in the scene, to align units",
    )  # fmt: skip
    cen = p.add_argument_group("centroid (video cameras, passive markers)")
    cen.add_argument(
        "--markers", type=int, default=None,
        help="markers: on the walking body (default 40), on the wand (2 or 3, default 3), "
        "of the L-frame (default 4); coda: in the scene, IDs 1..M (default 8)",
    )  # fmt: skip
    cen.add_argument(
        "--wand-length", type=float, default=500.0, metavar="MM",
        help="wand: distance between its end markers (default 500 mm); a 3-marker wand's "
        "middle marker sits 0.4 of it from end A",
    )  # fmt: skip
    cen.add_argument(
        "--ghosts", type=float, default=0.02, metavar="RATE",
        help="fraction of (camera, marker) pairs that see a floor-reflection ghost (0.02)",
    )  # fmt: skip
    cen.add_argument("--noise-blobs", type=float, default=0.02, help="noise blobs per image")
    cen.add_argument(
        "--sunlight", action="append", default=[], metavar="[CAM@]AT:DURATION",
        help="camera CAM (1 to --cameras, default 1) sees thousands of blobs from AT s "
        "after START:; repeat",
    )  # fmt: skip
    cen.add_argument(
        "--camera-off", action="append", default=[], metavar="CAM@AT:DURATION",
        help="camera CAM (1 to --cameras) delivers no frames from AT s after START:; repeat",
    )  # fmt: skip
    cen.add_argument("--no-occlusion", action="store_true", help="body segments hide nothing")
    cen.add_argument(
        "--model-out", type=Path, metavar="MODEL.json",
        help="write the markers' model (truth labels, rigid clusters, distance links) as JSON "
        "for spotlab record --model / spotlab reconstruct --model",
    )  # fmt: skip
    p.add_argument(
        "--port", type=int, default=0,
        help="qualisys, wsx: TCP port; natnet: UDP command port; on 127.0.0.1 (0: any free)",
    )  # fmt: skip
    sim_natnet.add_arguments(p)
    sim_wsx.add_arguments(p)
    p.add_argument("--seconds", type=float, help="stop by itself after this many seconds")
    add_qualisys_arguments(p)
    p.set_defaults(run=run)


def options_from_args(args: argparse.Namespace) -> service.SelspotSimOptions:
    """Simulator options from parsed command-line arguments."""
    cameras = 2 if args.cameras is None else args.cameras
    if not 1 <= cameras <= 4:
        raise CommandError(f"--cameras must be 1 to 4, got {cameras}")
    if not 1 <= args.leds <= 128:
        raise CommandError(f"--leds must be 1 to 128, got {args.leds}")
    if not args.rate > 0:
        raise CommandError(f"--rate must be positive, got {args.rate}")
    if not 0.0 <= args.reflectance <= 1.0:
        raise CommandError(f"--reflectance must be 0 to 1, got {args.reflectance}")
    motion = args.motion or "wand"
    if motion not in MOTIONS and not Path(motion).is_file():
        raise CommandError(f"--motion {motion!r} is neither {', '.join(MOTIONS)} nor a C3D file")
    return service.SelspotSimOptions(
        cameras=cameras,
        leds=args.leds,
        rate_hz=args.rate,
        seed=args.seed,
        truth=args.truth,
        fault_log=args.fault_log,
        faults=args.faults,
        clock_offset_s=args.clock_offset,
        clock_drift_ppm=args.clock_drift_ppm,
        clock_jitter_s=args.clock_jitter,
        clock_steps=clock_steps_from_args(args),
        motion=motion,
        floor_reflectance=args.reflectance,
        rig_out=args.rig_out,
        ring_phase_deg=getattr(args, "ring_phase", 0.0),
        scene_epoch_s=getattr(args, "scene_epoch", None),
        lab_name=getattr(args, "lab_name", None) or "selspot",
        lab=getattr(args, "lab", None),
    )


def _write_frame_points(path: Path, options: service.SelspotSimOptions) -> None:
    """The static markers' coordinates of the simulated motion, for ``spotlab calibrate``."""
    check_output_paths([("--frame-points-out", path)])
    try:
        points = static_points(make_motion(options.motion, options.leds, options.seed))
    except (OSError, ValueError) as exc:
        raise CommandError(f"--motion {options.motion}: {exc}") from None
    if not points:
        raise CommandError(
            f"--frame-points-out: --motion {options.motion} with --leds {options.leds} has no "
            "static markers (use --motion lframe, or more LEDs than the motion moves)"
        )
    rows = [f"{i + 1},{x:g},{y:g},{z:g}\n" for i, _label, (x, y, z) in points]
    path.write_text("marker,X,Y,Z\n" + "".join(rows))


def clock_steps_from_args(args: argparse.Namespace) -> tuple[tuple[float, float], ...]:
    """``--clock-step AT:DELTA`` options as ``(at_s, delta_s)`` pairs."""
    steps = []
    for item in getattr(args, "clock_step", None) or []:
        at, sep, delta = str(item).partition(":")
        try:
            if not sep:
                raise ValueError
            at_s, delta_s = float(at), float(delta)
        except ValueError:
            raise CommandError(f"--clock-step {item!r}: expected AT:DELTA in seconds") from None
        if not at_s >= 0:
            raise CommandError(f"--clock-step {item!r}: AT must be >= 0 s")
        steps.append((at_s, delta_s))
    return tuple(steps)


def timer_options_from_args(args: argparse.Namespace) -> service.TimerSimOptions:
    """Timer simulator options from parsed command-line arguments."""
    if not 1.0 <= args.rate <= 10_000.0:
        raise CommandError(f"--rate must be 1 to 10000 Hz, got {args.rate}")
    options = service.TimerSimOptions(
        rate_hz=args.rate,
        seed=args.seed,
        truth=args.truth,
        fault_log=args.fault_log,
        faults=args.faults,
        clock_offset_s=args.clock_offset,
        clock_drift_ppm=args.clock_drift_ppm,
        clock_jitter_s=args.clock_jitter,
        clock_steps=clock_steps_from_args(args),
        inputs=",".join(args.input),
        lab=args.lab,
    )
    try:
        options.validate()
    except ValueError as exc:
        raise CommandError(f"--input: {exc}") from None
    return options


def _episodes(items: list[str], option: str, cameras: int, *, default_camera: bool) -> str:
    """``[CAM@]AT:DURATION`` options, cameras counted from 1 as everywhere on the command
    line, as the simulator's ``CAM@AT:DURATION`` list (cameras counted from 0)."""
    out = []
    for item in items:
        cam, sep, rest = item.partition("@")
        if not sep:
            if not default_camera:
                raise CommandError(f"{option} {item!r}: expected CAM@AT:DURATION")
            cam, rest = "1", item
        try:
            number = int(cam)
        except ValueError:
            raise CommandError(f"{option} {item!r}: CAM must be a camera number") from None
        if not 1 <= number <= cameras:
            raise CommandError(f"{option} {item!r}: cameras are numbered 1 to {cameras}")
        out.append(f"{number - 1}@{rest}")
    return ",".join(out)


def centroid_options_from_args(args: argparse.Namespace) -> CentroidSimOptions:
    """Video-centroid simulator options from parsed command-line arguments."""
    cameras = 8 if args.cameras is None else args.cameras
    sun = _episodes(args.sunlight, "--sunlight", cameras, default_camera=True)
    off = _episodes(args.camera_off, "--camera-off", cameras, default_camera=False)
    motion = args.motion or "walk"
    if motion not in CENTROID_MOTIONS:
        raise CommandError(
            f"--motion {motion!r}: the centroid simulator plays {', '.join(CENTROID_MOTIONS)}"
        )
    markers = args.markers
    if markers is None:
        markers = {"wand": 3, "lframe": LFRAME_MARKERS}.get(motion, 40)
    options = CentroidSimOptions(
        cameras=cameras, markers=markers, motion=motion,
        wand_length_mm=args.wand_length, frame_points_out=args.frame_points_out,
        rate_hz=args.rate, seed=args.seed, truth=args.truth, fault_log=args.fault_log,
        rig_out=args.rig_out, faults=args.faults, clock_offset_s=args.clock_offset,
        clock_drift_ppm=args.clock_drift_ppm, clock_jitter_s=args.clock_jitter,
        ghost_rate=args.ghosts, noise_blobs=args.noise_blobs, sunlight=sun,
        camera_off=off, occlusion=0 if args.no_occlusion else 1,
        lab_name=args.lab_name or "centroid", lab=args.lab,
    )  # fmt: skip
    try:
        options.validate()
    except ValueError as exc:
        raise CommandError(str(exc)) from None
    return options


def coda_options_from_args(args: argparse.Namespace) -> CodaSimOptions:
    """Scanner simulator options from parsed command-line arguments (``--rate`` default 300)."""
    options = CodaSimOptions(
        markers=8 if args.markers is None else args.markers,
        rate_hz=args.rate if getattr(args, "rate_given", False) else 300.0,
        seed=args.seed, truth=args.truth, fault_log=args.fault_log, faults=args.faults,
        clock_offset_s=args.clock_offset, clock_drift_ppm=args.clock_drift_ppm,
        clock_jitter_s=args.clock_jitter, lab_name=args.lab_name or "coda", lab=args.lab,
        pose=args.pose, reference=int(args.reference),
    )  # fmt: skip
    try:
        options.validate()
    except ValueError as exc:
        raise CommandError(str(exc)) from None
    return options


def check_args(args: argparse.Namespace) -> None:
    """Refuse what would fail once the device serves: bad output paths, lab folder,
    fault schedule or motion file (a failure in the serving thread is no clear error)."""
    check_output_paths(
        [
            ("--truth", args.truth),
            ("--fault-log", args.fault_log),
            ("--rig-out", args.rig_out),
            ("--model-out", getattr(args, "model_out", None)),
            ("--frame-points-out", getattr(args, "frame_points_out", None)),
        ]
    )
    check_output_dir("--lab" if args.lab is not None else "lab folder", lab_dir(args.lab))
    try:
        parse_schedule(args.faults)
    except ValueError as exc:
        raise CommandError(f"--faults: {exc}") from None
    motion = str(args.motion)
    if args.family == "selspot" and motion not in MOTIONS and Path(motion).is_file():
        try:
            from_c3d(motion)
        except (ValueError, FileFormatError) as exc:
            raise CommandError(f"--motion: {exc}") from None


def run(args: argparse.Namespace) -> int:
    if args.family == "qualisys":
        return run_qualisys(args)
    if args.family == "natnet":
        return sim_natnet.run(args)
    if args.family == "wsx":
        return sim_wsx.run(args)
    check_args(args)
    if args.family == "centroid":
        if args.tcp is not None:
            raise CommandError("the centroid simulator serves on a pseudo-terminal only (--pty)")
        options = centroid_options_from_args(args)
        if args.model_out is not None and options.motion != "walk":
            raise CommandError(
                "--model-out: the marker model is the walking body's (--motion walk)"
            )
        if args.model_out is not None:
            # the simulator's own output: its body's model, learnt from its true walk
            MarkerModel.infer(*model_walk(options.markers, options.seed)).save(args.model_out)
        return _serve(args, serve_centroid_pty(options))
    if args.family == "coda":
        options = coda_options_from_args(args)
        server = serve_coda_tcp(options, port=args.tcp) if args.tcp is not None else None
        return _serve(args, server if server is not None else serve_coda_pty(options))
    if args.family == "timer":
        if args.tcp is not None:
            raise CommandError("the timer simulator serves on a pseudo-terminal only (--pty)")
        return _serve(args, service.serve_timer_pty(timer_options_from_args(args)))
    if args.input:
        raise CommandError("--input wires timer inputs; selspot systems have none")
    options = options_from_args(args)
    if args.frame_points_out is not None:
        _write_frame_points(args.frame_points_out, options)
    server = (
        service.serve_tcp(options, port=args.tcp)
        if args.tcp is not None
        else service.serve_pty(options)
    )
    return _serve(args, server)


def _serve(args: argparse.Namespace, server: PtyServer | TcpServer) -> int:
    stop = threading.Event()

    def _stop(signum: int, frame: object) -> None:
        stop.set()

    signal.signal(signal.SIGTERM, _stop)
    signal.signal(signal.SIGINT, _stop)
    try:
        print(server.url if args.tcp is not None else server.path, flush=True)
        stop.wait(args.seconds)
    finally:
        server.stop()
    sys.stdout.flush()
    return 0
