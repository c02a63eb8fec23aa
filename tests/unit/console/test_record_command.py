"""``spotlab record``: per-device settings, devices keeping their own settings, lab files,
journals without the .spj suffix, and one count shared with ``spotlab info``.

The devices are the in-process simulators (``sim://`` URLs, real pyserial port objects);
the pseudo-terminal runs are in tests/hil/test_e2e_lab.py.
"""

from __future__ import annotations

import json
import os
import signal
import threading
import time
from pathlib import Path

import pytest

import spotlab.simulators  # noqa: F401  (registers sim://)
from spotlab.acquisition.realtime import probe
from spotlab.console.cli import main
from spotlab.io import read_c3d, read_trc
from spotlab.io.journal import JournalReader
from spotlab.io.lab_file import LabFileError, load_lab


def _record(capsys: pytest.CaptureFixture[str], *args: object) -> dict:
    code = main(["record", *(str(a) for a in args), "--json"])
    out = capsys.readouterr()
    assert code == 0, out.err
    result: dict = json.loads(out.out)
    return result


def _info(capsys: pytest.CaptureFixture[str], path: Path) -> dict:
    assert main(["info", str(path), "--json"]) == 0
    info: dict = json.loads(capsys.readouterr().out)
    return info


def _one_error(capsys: pytest.CaptureFixture[str], code: int, *needles: str) -> str:
    err = capsys.readouterr().err
    lines = [x for x in err.splitlines() if x.startswith("spotlab: error:")]
    assert code != 0 and len(lines) == 1 and "Traceback" not in err, err
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])
    return lines[0]


def _rates(path: Path) -> dict[str, float]:
    streams = JournalReader(path).streams
    return {name: float(meta["spec"]["rate_hz"]) for name, meta in streams.items()}


def test_each_device_at_its_own_rate(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "rec.spj"
    _record(
        capsys,
        "--device", "selspot=sim://selspot?seed=1,rate=200,cameras=2,leds=4",
        "--device", "selspot=sim://selspot?seed=2,rate=150,cameras=1,leds=6",
        "--device", "timer=sim://timer,rate=100",
        "--seconds", 1.0, "--out", out,
    )  # fmt: skip
    assert _rates(out) == {"selspot0": 200.0, "selspot1": 150.0, "timer": 100.0}
    streams = JournalReader(out).streams
    assert streams["selspot0"]["spec"]["n_sensors"] == 2
    assert streams["selspot1"]["spec"]["n_markers"] == 6
    for s in _info(capsys, out)["streams"]:
        assert s["rate_hz"] == pytest.approx(_rates(out)[s["name"]], rel=0.01)


def test_global_options_are_defaults_for_devices_that_do_not_say(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "rec.spj"
    _record(
        capsys,
        "--device", "selspot=sim://selspot,rate=200",
        "--device", "timer=sim://timer",
        "--rate", 50, "--leds", 3, "--seconds", 0.3, "--out", out,
    )  # fmt: skip
    assert _rates(out) == {"selspot": 200.0, "timer": 50.0}
    assert JournalReader(out).streams["selspot"]["spec"]["n_markers"] == 3


@pytest.mark.parametrize(
    ("device", "needles"),
    [
        ("selspot=sim://selspot,bogus=1", ("'bogus'", "selspot")),
        ("timer=sim://timer,cameras=2", ("'cameras'", "timer")),
        ("selspot=sim://selspot,rate=fast", ("rate='fast'", "frame rate")),
        ("centroid=sim://centroid,blobs=1.5", ("blobs=1.5",)),
    ],
)
def test_a_bad_setting_is_one_error_naming_it(
    device: str, needles: tuple[str, ...], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code = main(["record", "--device", device, "--seconds", "1", "--out", str(tmp_path / "x")])
    _one_error(capsys, code, *needles)
    assert not (tmp_path / "x").exists()


@pytest.mark.parametrize(
    ("family", "url", "rate"),
    [
        ("selspot", "sim://selspot?rate=200&seed=4", 200.0),
        ("timer", "sim://timer?rate=150", 150.0),
        ("centroid", "sim://centroid?rate=300&cameras=2&seed=5", 300.0),
    ],
)
def test_a_device_keeps_its_own_rate_when_none_is_given(
    family: str, url: str, rate: float, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "rec.spj"
    _record(capsys, url, "--driver", family, "--seconds", 0.5, "--out", out)
    assert _rates(out) == {family: rate}
    (stream,) = _info(capsys, out)["streams"]
    assert stream["rate_hz"] == pytest.approx(rate, rel=0.01)


def test_the_record_summary_is_the_info_summary(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """With bit flips and dropped bytes on the line both report the same counts."""
    out = tmp_path / "rec.spj"
    url = "sim://selspot?seed=7&faults=bitflip@0.2,bitflip@0.4,drop@0.6,bitflip@0.8"
    result = _record(capsys, url, "--driver", "selspot", "--seconds", 1.2, "--out", out)
    info = _info(capsys, out)
    keys = ("frames", "lost_frames", "crc_errors", "resyncs", "reconnects", "gaps")
    (rec,), (inf,) = result["streams"], info["streams"]
    assert {k: rec[k] for k in keys} == {k: inf[k] for k in keys}
    assert inf["crc_errors"] + inf["lost_frames"] > 0  # the faults are in the file


def test_a_journal_without_suffix_is_read_by_every_command(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "rec"
    _record(
        capsys,
        "--device", "selspot=sim://selspot?seed=3&cameras=3&leds=6"
        f"&rig_out={tmp_path / 'rig.toml'},cameras=3,leds=6",
        "--device", "timer=sim://timer", "--seconds", 0.6, "--out", out,
    )  # fmt: skip
    ts = tmp_path / "ts.csv"
    assert main(["export", str(out), "--timestamps", str(ts)]) == 0, capsys.readouterr().err
    assert ts.read_text().count("\n") > 60
    c3d = tmp_path / "t.c3d"
    code = main(
        ["export", str(out), "--calibration", str(tmp_path / "rig.toml"), "--c3d", str(c3d)]
    )
    assert code == 0, capsys.readouterr().err
    assert c3d.stat().st_size > 0


def _lab(folder: Path, text: str) -> Path:
    path = folder / "lab.toml"
    path.write_text(text)
    return path


def test_a_lab_file_records_its_devices_and_stores_the_wiring(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    model = {
        "labels": ["a", "b", "c"],
        "segments": [
            {
                "name": "s",
                "markers": ["a", "b", "c"],
                "coordinates_mm": [[0, 0, 0], [100, 0, 0], [0, 80, 0]],
            }
        ],
    }
    (tmp_path / "model.json").write_text(json.dumps(model))
    lab = _lab(
        tmp_path,
        'rig = "rig.toml"\nmodel = "model.json"\n\n'
        '[[device]]\nfamily = "selspot"\nport = "sim://selspot?seed=1"\nname = "left"\n'
        "rate = 200\nleds = 4\n\n"
        '[[device]]\nfamily = "timer"\nport = "sim://timer"\nrate = 100\n\n'
        "[wiring]\nleft = 3\n",
    )
    out = tmp_path / "rec.spj"
    _record(capsys, "--lab", lab, "--seconds", 0.4, "--out", out)
    reader = JournalReader(out)
    assert _rates(out) == {"left": 200.0, "timer": 100.0}
    assert reader.session["timer_wiring"] == {"left": 3}
    assert reader.session["lab"]["rig"] == str(tmp_path / "rig.toml")
    assert reader.session["marker_model"]["labels"] == ["a", "b", "c"]


@pytest.mark.parametrize(
    ("text", "needles"),
    [
        ("[[device]]\nfamily = 'selspot'\n", ("device[0].port",)),
        ("colour = 'red'\n[[device]]\nfamily = 'timer'\nport = 'x'\n", ("colour", "unknown")),
        ("[[device]]\nfamily = 'timer'\nport = 'x'\n[wiring]\na = 9\n", ("wiring.a", "0-7")),
        ("[[device]]\nfamily = 'timer'\nport = 'x'\nleds = 3\n", ("device[0]", "'leds'")),
        ("[[device]\n", ("not TOML",)),
        ("[[device]]\nfamily = 'timer'\nport = 'x'\nrate = [1]\n", ("device[0].rate",)),
    ],
)
def test_a_bad_lab_file_is_one_error_naming_file_and_key(
    text: str, needles: tuple[str, ...], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    lab = _lab(tmp_path, text)
    code = main(["record", "--lab", str(lab), "--seconds", "1", "--out", str(tmp_path / "r")])
    _one_error(capsys, code, str(lab), *needles)


def test_load_lab_resolves_paths_against_the_file(tmp_path: Path) -> None:
    lab = load_lab(
        _lab(tmp_path, 'rig = "sub/rig.toml"\n[[device]]\nfamily = "timer"\nport = "p"\n')
    )
    assert lab.rig == tmp_path / "sub" / "rig.toml" and lab.model is None
    assert lab.devices[0].settings == {} and lab.wiring == {}
    with pytest.raises(LabFileError, match="cannot read"):
        load_lab(tmp_path / "missing.toml")


def test_ctrl_c_ends_an_open_ended_recording_with_its_summary(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """No --seconds: SIGINT (Ctrl-C) once frames are in the file is a deliberate stop."""
    out = tmp_path / "rec.spj"
    seen: list[int] = []

    def interrupt_when_recorded() -> None:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            if out.exists() and out.stat().st_size > 20_000:  # a few hundred 1 x 8 frames
                seen.append(out.stat().st_size)
                os.kill(os.getpid(), signal.SIGINT)
                return
            time.sleep(0.05)

    thread = threading.Thread(target=interrupt_when_recorded)
    thread.start()
    try:
        code = main(["record", "sim://selspot?seed=2", "--driver", "selspot", "--out", str(out)])
    finally:
        thread.join()
    captured = capsys.readouterr()
    assert seen and code == 0, captured.err
    assert "error" not in captured.err
    (line,) = captured.out.splitlines()
    frames = int(line.split(": ")[1].split(" frames")[0])
    (stream,) = _info(capsys, out)["streams"]
    assert frames == stream["frames"] > 100 and stream["lost_frames"] == 0
    assert JournalReader(out).complete


def test_the_lab_files_rig_reconstructs_its_recordings(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rig = tmp_path / "rig.toml"
    url = f"sim://selspot?seed=3&cameras=3&leds=6&rig_out={rig}"
    lab = _lab(
        tmp_path,
        f'rig = "rig.toml"\n[[device]]\nfamily = "selspot"\nport = "{url}"\n'
        "cameras = 3\nleds = 6\nrate = 100\n",
    )
    out = tmp_path / "rec.spj"
    _record(capsys, "--lab", lab, "--seconds", 0.5, "--out", out)
    c3d, trc = tmp_path / "t.c3d", tmp_path / "t.trc"
    assert main(["export", str(out), "--c3d", str(c3d)]) == 0, capsys.readouterr().err
    assert main(["reconstruct", str(out), "--out", str(trc)]) == 0, capsys.readouterr().err
    assert read_c3d(c3d).n_frames == read_trc(trc).n_frames > 30
    capsys.readouterr()
    # a recording made without a lab file still needs --calibration
    plain = tmp_path / "plain.spj"
    _record(capsys, "sim://selspot?seed=4", "--driver", "selspot", "--seconds", 0.2, "--out", plain)
    code = main(["reconstruct", str(plain), "--out", str(tmp_path / "p.trc")])
    _one_error(capsys, code, "--calibration", "names no rig")


def test_realtime_records_and_reports_its_policy(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "rt.spj"
    result = _record(
        capsys, "sim://selspot?seed=3", "--driver", "selspot", "--seconds", 0.3,
        "--realtime", 5, "--out", out,
    )  # fmt: skip
    refused = probe(5)
    assert result["realtime"] == {"priority": 5, "refused": refused}
    assert result["streams"][0]["frames"] > 0


@pytest.mark.parametrize(("value", "needle"), [("0", "1-99, got 0"), ("x", "got 'x'")])
def test_a_bad_realtime_priority_is_one_error(
    value: str, needle: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "r.spj"
    with pytest.raises(SystemExit) as exc:  # a usage error: argparse's exit code 2
        main(["record", "sim://selspot", "--realtime", value, "--seconds", "1", "--out", str(out)])
    _one_error(capsys, int(exc.value.code or 0), "--realtime", needle)
    assert not out.exists()
