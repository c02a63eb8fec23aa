"""Trials we write read back identically in our reader, the c3d package and ezc3d."""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
from ezc3d_child import ezc3d_dump

from spotlab.core.errors import RecordingError
from spotlab.io import Trial, read_c3d, write_c3d
from spotlab.io.trial import FileFormatError


def _f32(a: np.ndarray) -> np.ndarray:
    return a.astype(np.float32).astype(np.float64)


def _trial(frames: int = 60, markers: int = 4, channels: int = 3, per_frame: int = 5) -> Trial:
    rng = np.random.default_rng(4)
    points = _f32(rng.normal(0.0, 800.0, (frames, markers, 3)))
    points[3, 1] = np.nan
    points[10:20, 2] = np.nan
    return Trial(
        points=points,
        labels=[f"M{i}" for i in range(markers)],
        point_rate=100.0,
        analog=_f32(rng.normal(0.0, 2.0, (frames * per_frame, channels))),
        analog_labels=[f"EMG{i}" for i in range(channels)],
        analog_rate=100.0 * per_frame,
        first_frame=7,
        events=[("Foot Strike", "Left", 0.25), ("Foot Off", "Right", 61.5)],
    )


def _read_with_c3d_package(path: Path) -> tuple[np.ndarray, np.ndarray, object]:
    c3d = pytest.importorskip("c3d")
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="No analog data found", category=UserWarning)
        with open(path, "rb") as handle:
            reader = c3d.Reader(handle)
            frames = list(reader.read_frames())
            labels = [s.strip() for s in reader.point_labels]
    pts = np.array([p for _, p, _ in frames])
    xyz = np.where(pts[:, :, 3:4] < 0, np.nan, pts[:, :, :3].astype(np.float64))
    analog = np.concatenate([a.T for _, _, a in frames]) if frames[0][2].size else np.zeros(0)
    return xyz, analog, (frames[0][0], labels)


def test_round_trip_in_our_reader(tmp_path: Path) -> None:
    trial = _trial()
    path = tmp_path / "t.c3d"
    write_c3d(path, trial)
    back = read_c3d(path)
    assert np.array_equal(back.points, trial.points, equal_nan=True)
    assert np.array_equal(back.analog, trial.analog)
    assert back.labels == trial.labels and back.analog_labels == trial.analog_labels
    assert (back.point_rate, back.analog_rate, back.first_frame) == (100.0, 500.0, 7)
    assert back.events == trial.events
    assert back.metadata["notes"] == []


def test_round_trip_in_the_c3d_package(tmp_path: Path) -> None:
    trial = _trial()
    path = tmp_path / "t.c3d"
    write_c3d(path, trial)
    xyz, analog, (first, labels) = _read_with_c3d_package(path)
    assert np.array_equal(xyz, trial.points, equal_nan=True)
    assert np.array_equal(analog, trial.analog)
    assert first == 7 and labels == trial.labels


@pytest.mark.parametrize("channels", [3, 0])
def test_round_trip_in_ezc3d(tmp_path: Path, channels: int) -> None:
    trial = _trial(channels=channels)
    path = tmp_path / "t.c3d"
    write_c3d(path, trial)
    dump = ezc3d_dump(path, tmp_path / "dump.npz", ("POINT:LABELS", "ANALOG:LABELS", "POINT:RATE"))
    assert np.array_equal(dump["points"], trial.points, equal_nan=True)
    assert dump["first"] == trial.first_frame - 1  # ezc3d counts from 0
    assert dump["last"] == trial.first_frame - 1 + trial.n_frames - 1
    assert dump["params"]["POINT:LABELS"] == trial.labels
    assert dump["params"]["POINT:RATE"] == [100.0]
    if channels:
        assert np.array_equal(dump["analog"], trial.analog)
        assert dump["params"]["ANALOG:LABELS"] == trial.analog_labels


def test_more_than_65535_frames(tmp_path: Path) -> None:
    """POINT:FRAMES is capped; TRIAL:ACTUAL_START/END_FIELD carry the range; every frame is back."""
    frames = 70_000
    rng = np.random.default_rng(5)
    points = _f32(rng.normal(0.0, 300.0, (frames, 2, 3)))
    points[66_000:66_010, 1] = np.nan
    trial = Trial(points=points, labels=["A", "B"], point_rate=200.0)
    path = tmp_path / "long.c3d"
    write_c3d(path, trial)
    back = read_c3d(path)
    assert back.n_frames == frames and back.first_frame == 1
    assert np.array_equal(back.points, points, equal_nan=True)
    xyz, _, (first, _) = _read_with_c3d_package(path)
    assert first == 1 and xyz.shape == (frames, 2, 3)
    assert np.array_equal(xyz, points, equal_nan=True)


def test_points_not_in_mm_are_refused(tmp_path: Path) -> None:
    trial = _trial(channels=0)
    trial.units = "m"
    with pytest.raises(FileFormatError, match="in mm"):
        write_c3d(tmp_path / "m.c3d", trial)


@pytest.mark.parametrize(
    ("content", "cause"),
    [
        (b"", "not a readable C3D file"),
        (b"\x02P" + b"\x00" * 100, "not a readable C3D file"),
        (bytes(range(256)) * 8, "not a readable C3D file"),
    ],
)
def test_garbage_is_refused(tmp_path: Path, content: bytes, cause: str) -> None:
    path = tmp_path / "bad.c3d"
    path.write_bytes(content)
    with pytest.raises(RecordingError, match=cause) as info:
        read_c3d(path)
    assert str(path) in str(info.value)


def test_missing_file_is_refused(tmp_path: Path) -> None:
    with pytest.raises(RecordingError, match="cannot read the file"):
        read_c3d(tmp_path / "absent.c3d")


def test_truncated_file_reads_what_is_there(tmp_path: Path) -> None:
    path = tmp_path / "t.c3d"
    trial = _trial(channels=0)
    write_c3d(path, trial)
    data = path.read_bytes()
    path.write_bytes(data[:-1000])  # the last frames and the block padding are lost
    back = read_c3d(path)
    assert 0 < back.n_frames < trial.n_frames
    assert np.array_equal(back.points, trial.points[: back.n_frames], equal_nan=True)
    assert any("declared" in note for note in back.metadata["notes"])


def test_inconsistent_trial_is_refused(tmp_path: Path) -> None:
    trial = _trial()
    trial.analog = trial.analog[:-1]
    with pytest.raises(FileFormatError, match="analog samples"):
        write_c3d(tmp_path / "x.c3d", trial)
    trial = _trial()
    trial.labels = trial.labels[:-1]
    with pytest.raises(FileFormatError, match="labels"):
        write_c3d(tmp_path / "x.c3d", trial)
    with pytest.raises(FileFormatError, match="cannot write"):
        write_c3d(tmp_path / "no" / "dir.c3d", _trial())


def test_damaged_files_are_read_or_refused(shared_data: Path, tmp_path: Path) -> None:
    """Seeded truncations and byte changes: a Trial or a FileFormatError, nothing else."""
    rng = np.random.default_rng(11)
    sources = [
        shared_data / "c3d_org_samples/sample02/pc_int.c3d",
        shared_data / "c3d_org_samples/sample02/dec_real.c3d",
        shared_data / "c3d_org_samples/sample02/sgi_real.c3d",
    ]
    originals = [p.read_bytes() for p in sources]
    path = tmp_path / "damaged.c3d"
    outcomes = {"read": 0, "refused": 0}
    for k in range(240):
        data = bytearray(originals[k % len(originals)])
        if k % 3 == 0:
            data = data[: int(rng.integers(0, len(data)))]
        else:
            limit = 512 * 2 if k % 3 == 1 else len(data)  # header and parameters, or anywhere
            for _ in range(int(rng.integers(1, 20))):
                data[int(rng.integers(0, limit))] = int(rng.integers(0, 256))
        path.write_bytes(bytes(data))
        try:
            read_c3d(path)
            outcomes["read"] += 1
        except FileFormatError as exc:
            assert str(exc).startswith(str(path))
            outcomes["refused"] += 1
    assert outcomes["read"] > 0 and outcomes["refused"] > 0


def test_without_the_c3d_package(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """Reading and writing need no third-party C3D package (it only cross-checks in tests)."""
    monkeypatch.setitem(sys.modules, "c3d", None)  # import c3d now raises ImportError
    path = tmp_path / "t.c3d"
    write_c3d(path, _trial())
    back = read_c3d(path)
    assert np.array_equal(back.points, _trial().points, equal_nan=True)


@pytest.mark.parametrize("first", [65535, 65536, 70001, 200_000])
def test_first_frame_past_the_16_bit_header_survives(tmp_path: Path, first: int) -> None:
    # a trial on a session time grid starts late: 300 Hz x 220 s is past 65535
    trial = Trial(np.zeros((3, 1, 3)), ["a"], 300.0, first_frame=first)
    write_c3d(tmp_path / "late.c3d", trial)
    assert read_c3d(tmp_path / "late.c3d").first_frame == first


def test_unreadable_parameters_are_named_and_counted(tmp_path: Path) -> None:
    """A parameter of the wrong type is taken as absent, and the file's notes say which."""
    path = tmp_path / "t.c3d"
    trial = _trial()
    write_c3d(path, trial)
    data = bytearray(path.read_bytes())
    for name in (b"OFFSET", b"GEN_SCALE"):  # each occurs once: ANALOG's
        at = data.index(bytes([len(name)]) + bytes([data[data.index(name) - 1]]) + name)
        type_byte = at + 2 + len(name) + 2  # after the name and the 2-byte pointer
        assert data[type_byte] in (2, 4)
        data[type_byte] = 0xFF  # now a character parameter
    path.write_bytes(bytes(data))
    back = read_c3d(path)
    failures = back.metadata["unreadable_parameters"]
    assert [f.split(" ")[0] for f in failures] == ["ANALOG:OFFSET", "ANALOG:GEN_SCALE"]
    assert all("type -1" in f for f in failures)
    assert any(n.startswith("2 parameter(s) could not be read") for n in back.metadata["notes"])
    assert np.array_equal(back.analog, trial.analog)  # the defaults (0 and 1) were written


def test_more_than_255_markers_use_labels2(tmp_path: Path) -> None:
    """A parameter's dimensions are bytes: labels 256 on go to POINT:LABELS2 (ezc3d reads both)."""
    rng = np.random.default_rng(8)
    labels = [f"M{i:03d}" for i in range(300)]
    trial = Trial(_f32(rng.normal(0.0, 400.0, (5, 300, 3))), labels, 100.0)
    path = tmp_path / "many.c3d"
    write_c3d(path, trial)
    back = read_c3d(path)
    assert back.labels == labels
    assert np.array_equal(back.points, trial.points)
    params = back.metadata["c3d_parameters"]
    assert params.get("POINT:LABELS").dims == (4, 255)
    assert params.get("POINT:LABELS2").dims == (4, 45)
    dump = ezc3d_dump(path, tmp_path / "d.npz", ("POINT:LABELS", "POINT:LABELS2"))
    assert dump["points"].shape == (5, 300, 3)
    assert dump["params"]["POINT:LABELS"] + dump["params"]["POINT:LABELS2"] == labels


def test_parameters_survive_serialisation() -> None:
    """Every type and shape, a locked flag and descriptions, parsed back as written."""
    from spotlab.io.c3d_parameters import (
        C3DParameters,
        make_parameter,
        parse_parameters,
        serialize_parameters,
    )

    params = C3DParameters()
    params.put(make_parameter("POINT", "USED", 7, "points"))
    params.put(make_parameter("POINT", "LABELS", ["a", "long name"], "labels"))
    params.put(make_parameter("FORCE_PLATFORM", "CAL_MATRIX", np.arange(72.0).reshape(6, 6, 2)))
    params.put(make_parameter("FORCE_PLATFORM", "CHANNEL", np.arange(12).reshape(6, 2)))
    params.put(make_parameter("TRIAL", "NAME", "walk 3"))
    params.groups["POINT"]["USED"].locked = True
    params.descriptions["TRIAL"] = "the trial"
    back = parse_parameters(serialize_parameters(params), 84)
    assert back.notes == []
    for group, members in params.groups.items():
        assert list(back.groups[group]) == list(members)
        for name, param in members.items():
            assert back.groups[group][name] == param, (group, name)
    assert back.descriptions["TRIAL"] == "the trial"
    cal = back.get("FORCE_PLATFORM:CAL_MATRIX")
    assert cal.dims == (6, 6, 2) and cal.floats()[1] == 12.0  # [1, 0, 0]: first index fastest
    assert back.get("POINT:LABELS").strings() == ["a", "long name"]
