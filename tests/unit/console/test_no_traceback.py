"""Bad input to every subcommand: exactly one ``spotlab: error:`` line, a non-zero exit,
never a traceback (issue 12, section 3).

The CLI runs in-process (``spotlab.console.cli.main``) where it can; a Ctrl-C needs a
real process and a real signal. Every case fails before any device is served or any
work is done, so none of them leaves a thread or a file behind.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from spotlab.console.cli import COMMANDS, build_parser, main
from spotlab.console.commands.sim import centroid_options_from_args
from spotlab.simulators.faults import parse_schedule
from spotlab.simulators.rigs import ring_rig

ERROR = "spotlab: error:"


def _one_error(argv: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    """Run ``spotlab argv``; assert one error line and a non-zero exit; return that line."""
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse usage errors exit from the parser
        code = exc.code if isinstance(exc.code, int) else 1
    err = capsys.readouterr().err
    assert code != 0, (argv, err)
    assert "Traceback" not in err, err
    lines = [line for line in err.splitlines() if line.startswith(ERROR)]
    assert len(lines) == 1, err
    assert err.count(ERROR) == 1 and "spotlab: error: spotlab" not in err, err
    return lines[0]


@pytest.fixture
def files(tmp_path: Path) -> dict[str, Path]:
    """A regular file to put outputs under, a rig, and npz files with bad arrays."""
    plain = tmp_path / "plain.txt"
    plain.write_text("a regular file\n")
    rig = tmp_path / "rig.toml"
    ring_rig(2, seed=1).save(rig)
    strings = tmp_path / "strings.npz"
    np.savez(
        strings,
        wand=np.array(["a", "b"]),
        frame=np.zeros((2, 3, 2)),
        frame_points=np.zeros((3, 3)),
        image_size=np.array([1000, 1000]),
    )
    objects = tmp_path / "objects.npz"
    np.savez(objects, uv=np.array([{"a": 1}, None], dtype=object))
    bad_rate = tmp_path / "bad_rate.npz"
    np.savez(bad_rate, uv=np.zeros((3, 2, 1, 2)), rate="abc")
    garbage_c3d = tmp_path / "garbage.c3d"
    garbage_c3d.write_bytes(b"not a c3d file at all")
    return {
        "dir": tmp_path,
        "plain": plain,
        "rig": rig,
        "strings": strings,
        "objects": objects,
        "bad_rate": bad_rate,
        "garbage_c3d": garbage_c3d,
    }


# (id, argv from the files, words the error line must hold)
Case = tuple[str, Callable[[dict[str, Path]], list[str]], tuple[str, ...]]
CASES: list[Case] = [
    # outputs under a regular file
    *[
        (
            f"calibrate{flag}",
            lambda f, flag=flag, name=name: [
                "calibrate",
                str(f["strings"]),
                "--out",
                str(f["dir"] / "rig_out.toml"),
                flag,
                str(f["plain"] / name),
            ],
            (flag, "is a file"),
        )
        for flag, name in (("--out", "x.toml"), ("--report", "r.json"), ("--figure", "f.png"))
    ],
    *[
        (
            f"export{flag}",
            lambda f, flag=flag, name=name: [
                "export",
                str(f["dir"] / "rec.spj"),
                flag,
                str(f["plain"] / name),
            ],
            (flag, "is a file"),
        )
        for flag, name in (
            ("--timestamps", "t.csv"),
            ("--sync-report", "s.json"),
            ("--c3d", "x.c3d"),
            ("--trc", "x.trc"),
        )
    ],
    (
        "replay--timestamps",
        lambda f: ["replay", str(f["plain"]), "--timestamps", str(f["plain"] / "t.csv")],
        ("--timestamps", "is a file"),
    ),
    (
        "reconstruct--out",
        lambda f: [
            "reconstruct",
            str(f["bad_rate"]),
            "--calibration",
            str(f["rig"]),
            "--out",
            str(f["plain"] / "x.c3d"),
        ],
        ("--out", "is a file"),
    ),
    (
        "record--out",
        lambda f: [
            "record",
            "--device",
            "selspot=/dev/null",
            "--seconds",
            "1",
            "--out",
            str(f["plain"] / "x.spj"),
        ],
        ("--out", "is a file"),
    ),
    *[
        (
            f"sim-{family}{flag}",
            lambda f, family=family, flag=flag: [
                "sim",
                family,
                flag,
                str(f["plain"] / "x"),
                "--seconds",
                "0.1",
            ],
            (flag, "is a file"),
        )
        for family in ("selspot", "timer", "centroid")
        for flag in ("--truth", "--fault-log", "--rig-out")
    ],
    (
        "sim--model-out",
        lambda f: ["sim", "centroid", "--model-out", str(f["plain"] / "m.json")],
        ("--model-out", "is a file"),
    ),
    ("demo--out-file", lambda f: ["demo", "--out", str(f["plain"])], ("--out", "is a file")),
    ("sim--lab-file", lambda f: ["sim", "selspot", "--lab", str(f["plain"])], ("--lab",)),
    (
        "sim--fault-log-nodir",
        lambda f: ["sim", "selspot", "--fault-log", str(f["dir"] / "nodir" / "x.json")],
        ("--fault-log", "does not exist"),
    ),
    ("sim--faults-bogus", lambda f: ["sim", "selspot", "--faults", "bogus@1"], ("bogus",)),
    ("sim--faults-drop@x", lambda f: ["sim", "timer", "--faults", "drop@x"], ("drop@x",)),
    ("sim-centroid--faults", lambda f: ["sim", "centroid", "--faults", "@"], ("--faults",)),
    (
        "sim--motion-garbage",
        lambda f: ["sim", "selspot", "--motion", str(f["garbage_c3d"])],
        ("--motion", "garbage.c3d", "not a readable C3D"),
    ),
    ("sim--motion-missing", lambda f: ["sim", "selspot", "--motion", "nope"], ("nope",)),
    ("sim--clock-step", lambda f: ["sim", "selspot", "--clock-step", "x"], ("--clock-step",)),
    (
        "sim--camera-off-0",
        lambda f: ["sim", "centroid", "--camera-off", "0@1:1"],
        ("--camera-off", "numbered 1 to 8"),
    ),
    (
        "sim--sunlight-9",
        lambda f: ["sim", "centroid", "--cameras", "4", "--sunlight", "5@1:1"],
        ("--sunlight", "numbered 1 to 4"),
    ),
    # bad npz contents
    (
        "calibrate-string-array",
        lambda f: ["calibrate", str(f["strings"]), "--out", str(f["dir"] / "r.toml")],
        ("'wand'", "numbers"),
    ),
    (
        "reconstruct-object-array",
        lambda f: [
            "reconstruct",
            str(f["objects"]),
            "--calibration",
            str(f["rig"]),
            "--out",
            str(f["dir"] / "x.c3d"),
        ],
        ("'uv'", "python objects"),
    ),
    (
        "calibrate-object-array",
        lambda f: ["calibrate", str(f["objects"]), "--out", str(f["dir"] / "r.toml")],
        ("'uv'", "python objects"),
    ),
    (
        "reconstruct-rate-abc",
        lambda f: [
            "reconstruct",
            str(f["bad_rate"]),
            "--calibration",
            str(f["rig"]),
            "--out",
            str(f["dir"] / "x.c3d"),
        ],
        ("'rate'", "numbers"),
    ),
    (
        "model-learn--out",
        lambda f: ["model", "learn", str(f["garbage_c3d"]), "--out", str(f["plain"] / "m.json")],
        ("--out", "is a file"),
    ),
    (
        "model-learn-garbage",
        lambda f: ["model", "learn", str(f["garbage_c3d"]), "--out", str(f["dir"] / "m.json")],
        ("garbage.c3d",),
    ),
    ("model-show-plain", lambda f: ["model", "show", str(f["plain"])], ("plain.txt",)),
    ("model-usage", lambda f: ["model", "learn"], ("model learn:",)),
    # usage errors: one prefix, the subcommand named once
    ("record-usage", lambda f: ["record"], ("record:", "--out")),
    ("export-usage", lambda f: ["export"], ("export:",)),
    ("unknown-command", lambda f: ["nonsense"], ("nonsense",)),
    ("info-missing", lambda f: ["info", str(f["dir"] / "missing.spj")], ("missing.spj",)),
    ("info-plain", lambda f: ["info", str(f["plain"])], ("plain.txt",)),
    ("udev-bad", lambda f: ["udev", "--nonsense"], ("udev:",)),
    ("devices-bad", lambda f: ["devices", "--nonsense"], ("devices:", "--nonsense")),
    ("info-extra", lambda f: ["info", str(f["plain"]), "extra"], ("info:", "extra")),
    ("console-nolab", lambda f: ["console", "--no-browser"], ("--lab", "--sim")),
    (
        "console-host",
        lambda f: [
            "console",
            "--sim",
            "--host",
            "10.1.2.3",
            "--no-browser",
            "--data",
            str(f["dir"] / "data"),
        ],
        ("--token",),
    ),
    (
        "console-lab",
        lambda f: [
            "console",
            "--lab",
            str(f["dir"] / "missing.toml"),
            "--port",
            "0",
            "--no-browser",
            "--data",
            str(f["dir"] / "data"),
        ],
        ("missing.toml",),
    ),
    ("console-port", lambda f: ["console", "--sim", "--port", "70000"], ("--port",)),
    ("bench-usage", lambda f: ["bench"], ("nothing to bench",)),
    (
        "bench--report",
        lambda f: ["bench", "sim://selspot", "--driver", "selspot", "--report", str(f["plain"])],
        ("--report", "is a file"),
    ),
    ("bench-family", lambda f: ["bench", "x", "--driver", "lsl"], ("no conformance suite",)),
    ("hil-missing", lambda f: ["hil", "run", str(f["dir"] / "none.toml")], ("none.toml",)),
    ("hil-usage", lambda f: ["hil"], ("hil:",)),
]


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_bad_input_is_one_error_line(
    case: Case, files: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    _name, argv, needles = case
    line = _one_error(argv(files), capsys)
    for needle in needles:
        assert needle.lower() in line.lower(), (needle, line)


def test_every_subcommand_has_a_case() -> None:
    covered = {c[0].split("-")[0] for c in CASES}
    assert set(COMMANDS) <= covered | {"nonsense"}


def test_outputs_are_checked_before_the_work(
    files: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    """A bad --figure leaves no rig and no report behind (nothing is written)."""
    out = files["dir"] / "first.toml"
    _one_error(
        ["calibrate", str(files["strings"]), "--out", str(out),
         "--figure", str(files["plain"] / "f.png")],
        capsys,
    )  # fmt: skip
    assert not out.exists() and not out.with_suffix(".report.json").exists()


@settings(
    max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(text=st.text(alphabet="bitflpdrogaxe@:,.0123456789- ", max_size=30))
def test_any_fault_schedule_is_taken_or_refused_in_one_line(
    text: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Random --faults strings: a bad one is named; a good one reaches the next check
    (--leds 0, refused before serving), never a traceback."""
    line = _one_error(
        ["sim", "selspot", "--faults", text, "--leds", "0", "--lab", str(tmp_path)], capsys
    )
    try:
        parse_schedule(text)
    except ValueError:
        assert "--faults" in line, line
    else:
        assert "--leds" in line, line


@settings(
    max_examples=100, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(text=st.text(alphabet="0123456789.:-ex ", max_size=12))
def test_any_clock_step_is_taken_or_refused_in_one_line(
    text: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    _one_error(
        ["sim", "selspot", "--clock-step", text, "--leds", "0", "--lab", str(tmp_path)], capsys
    )


def test_sim_cameras_count_from_1_on_the_command_line() -> None:
    """``--sunlight`` / ``--camera-off`` take CAM from 1, as calibrate and reconstruct."""
    args = build_parser("sim").parse_args(
        ["sim", "centroid", "--cameras", "4", "--sunlight", "0.5:1", "--sunlight", "4@1:2",
         "--camera-off", "1@0.2:0.3"]
    )  # fmt: skip
    options = centroid_options_from_args(args)
    assert options.sunlight == "0@0.5:1,3@1:2"
    assert options.camera_off == "0@0.2:0.3"


def test_subcommand_help_lines_match_the_listing() -> None:
    """``spotlab --help`` shows each command's help line without importing its module;
    the line must be the one the module itself gives."""
    parser = build_parser("*")
    sub = next(a for a in parser._actions if a.dest == "command")
    shown = {action.dest: action.help for action in sub._choices_actions}
    assert shown == COMMANDS


def test_every_option_has_help() -> None:
    """Every option and positional of every subcommand says what it is for."""
    parser = build_parser("*")
    sub = next(a for a in parser._actions if a.dest == "command")
    missing = []
    for name, command in sub.choices.items():
        parsers = [(name, command)]
        for action in command._actions:
            if action.choices and isinstance(action.choices, dict):  # nested (udev ACTION)
                parsers += [(f"{name} {k}", p) for k, p in action.choices.items()]
        for label, p in parsers:
            for action in p._actions:
                if not action.help and action.dest != "help":
                    missing.append(f"{label} {'/'.join(action.option_strings) or action.dest}")
    assert missing == []


def test_version_imports_no_subcommand_and_no_numpy() -> None:
    code = (
        "import sys\n"
        "from spotlab.console.cli import main\n"
        "try:\n    main(['--version'])\nexcept SystemExit:\n    pass\n"
        "print(sorted(m for m in sys.modules if m.startswith('spotlab.console.commands')"
        " or m in ('numpy', 'scipy', 'matplotlib')))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.splitlines()[-1] == "[]", out.stdout


def _in_python_start_up(err: str) -> bool:
    """A KeyboardInterrupt traceback raised while the entry module and its imports were
    still loading (only module-level frames: ``main`` had not started), before any
    spotlab code that could take the signal ran."""
    frames = [line.strip() for line in err.splitlines() if line.strip().startswith("File ")]
    return (
        "KeyboardInterrupt" in err
        and bool(frames)
        and not any(f.endswith(" in main") for f in frames)
        and all(
            "<frozen " in f or f.endswith(" in <module>") or "/spotlab/" not in f for f in frames
        )
    )


@pytest.mark.parametrize("command", [["sim", "selspot"], ["demo"]])
@pytest.mark.parametrize("delay_s", [0.0, 0.3, 1.0, 2.5])
def test_ctrl_c_at_start_up(command: list[str], delay_s: float, tmp_path: Path) -> None:
    """SIGINT at any moment of start-up: a clean stop or one 'interrupted' line."""
    argv = [*command, "--lab", str(tmp_path)] if command[0] == "sim" else [
        *command, "--out", str(tmp_path / "demo")
    ]  # fmt: skip
    env = {**os.environ, "PYTHONWARNINGS": "ignore"}
    proc = subprocess.Popen(
        [sys.executable, "-m", "spotlab.console.cli", *argv],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
        cwd=tmp_path,
    )
    time.sleep(delay_s)
    proc.send_signal(signal.SIGINT)
    try:
        _out, err = proc.communicate(timeout=60)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.communicate()
        raise
    if "Traceback" in err and _in_python_start_up(err):
        # The signal came while Python was still loading spotlab's entry module and its
        # imports (runpy, module-level imports): main, which takes it, had not started.
        assert proc.returncode != 0, (proc.returncode, err)
        return
    assert "Traceback" not in err and "Exception ignored" not in err, err
    errors = [line for line in err.splitlines() if line.startswith(ERROR)]
    if proc.returncode == 0:  # the simulator was serving: Ctrl-C stops it
        assert errors == [], err
    else:
        # 130: spotlab caught it; -SIGINT: the signal came before Python could take it
        # (the process ends as a shell expects of Ctrl-C, silently).
        assert proc.returncode in (130, -signal.SIGINT), (proc.returncode, err)
        assert errors in ([], [f"{ERROR} interrupted"]), err
