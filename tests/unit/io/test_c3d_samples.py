"""Every shared C3D sample file is read, or refused with an error naming the file and the cause."""

from __future__ import annotations

import os
import warnings
from pathlib import Path

import numpy as np
import pytest

from spotlab.core.errors import RecordingError
from spotlab.io import Trial, read_c3d, write_c3d

# as tests/conftest.py SHARED_DATA: ../shared/data, or $SPOTLAB_SHARED_DATA
DATA = Path(
    os.environ.get("SPOTLAB_SHARED_DATA")
    or Path(__file__).resolve().parents[3].parent / "shared" / "data"
)
FOLDERS = ("c3d_org_samples", "ezc3d_testfiles", "bmc")
FILES = sorted(
    str(p.relative_to(DATA))
    for folder in FOLDERS
    for p in (DATA / folder).rglob("*")
    if p.suffix.lower() == ".c3d"
)

#: Files we refuse, and a piece of the message that says why. (sample18's damaged
#: parameter section and sample33's repeated parameters are read: test_c3d_other_labs.py.)
REFUSED = {
    # rotation matrices only (ROTATION group), no points or analog channels
    "ezc3d_testfiles/C3DRotationExample.c3d": "no point or analog data",
}

SAMPLE01 = [f"c3d_org_samples/sample01/Eb015{p}{s}.c3d" for p in "pvs" for s in "ir"]


def _read(shared_data: Path, name: str) -> Trial:
    return read_c3d(shared_data / name)


def test_the_shared_files_are_there(shared_data: Path) -> None:
    assert len(FILES) >= 56, FILES
    assert set(REFUSED) <= set(FILES)


@pytest.mark.parametrize("name", FILES)
def test_every_file_is_read_or_refused_clearly(shared_data: Path, name: str) -> None:
    path = shared_data / name
    if name in REFUSED:
        with pytest.raises(RecordingError) as info:
            read_c3d(path)
        assert str(path) in str(info.value)
        assert REFUSED[name] in str(info.value)
        return
    trial = read_c3d(path)
    f, m = trial.n_frames, trial.n_markers
    assert f > 0
    assert trial.points.shape == (f, m, 3) and trial.points.dtype == np.float64
    assert len(trial.labels) == m
    assert trial.point_rate > 0
    assert trial.units == "mm"
    seen = np.isfinite(trial.points)
    assert (seen == seen[:, :, :1]).all(), "a sample is missing in all three coordinates or none"
    a = trial.analog.shape[1]
    assert len(trial.analog_labels) == a
    if a:
        assert trial.analog.shape[0] == f * trial.analog_per_frame
        assert trial.analog_rate == pytest.approx(trial.point_rate * trial.analog_per_frame)


@pytest.mark.parametrize("name", [f for f in FILES if f not in REFUSED])
def test_every_readable_file_survives_our_writer(
    shared_data: Path, tmp_path: Path, name: str
) -> None:
    """Written back (float32 storage) and read again: the same trial."""
    trial = _read(shared_data, name)
    out = tmp_path / "copy.c3d"
    write_c3d(out, trial)
    back = read_c3d(out)

    def f32(a: np.ndarray) -> np.ndarray:
        return a.astype(np.float32).astype(np.float64)

    assert np.array_equal(back.points, f32(trial.points), equal_nan=True)
    assert np.array_equal(back.analog, f32(trial.analog))
    assert back.labels == trial.labels and back.analog_labels == trial.analog_labels
    assert back.point_rate == pytest.approx(trial.point_rate, rel=1e-7)
    assert back.analog_rate == pytest.approx(trial.analog_rate, rel=1e-7)
    assert back.first_frame == max(trial.first_frame, 1)
    assert [e[:2] for e in back.events] == [e[:2] for e in trial.events]
    assert np.allclose([e[2] for e in back.events], [e[2] for e in trial.events], atol=1e-4)


def test_sample01_six_processor_variants_are_identical(shared_data: Path) -> None:
    trials = [_read(shared_data, name) for name in SAMPLE01]
    ref = trials[0]
    assert ref.points.shape == (450, 26, 3)
    assert ref.analog.shape == (450 * 4, 16)
    assert (ref.point_rate, ref.analog_rate, ref.first_frame) == (50.0, 200.0, 1)
    assert ref.metadata["point_scale"] == pytest.approx(0.083333, abs=1e-6)
    # 11 474 valid point samples (SOURCES.md §1a)
    assert int(np.isfinite(ref.points[:, :, 0]).sum()) == 11474
    assert len(ref.events) == 3 and len(ref.metadata["header_events"]) == 3
    for name, trial in zip(SAMPLE01[1:], trials[1:], strict=True):
        assert np.array_equal(trial.points, ref.points, equal_nan=True), name
        assert np.array_equal(trial.analog, ref.analog), name
        assert trial.labels == ref.labels and trial.analog_labels == ref.analog_labels
        assert {p["processor"] for p in (trial.metadata, ref.metadata)} <= {"INTEL", "DEC", "MIPS"}
    processors = {t.metadata["processor"] for t in trials}
    storages = {t.metadata["storage"] for t in trials}
    assert processors == {"INTEL", "DEC", "MIPS"} and storages == {"integer", "float"}


def test_sample08_header_pointers(shared_data: Path) -> None:
    ref = _read(shared_data, "c3d_org_samples/sample08/EB015PI.c3d")
    for name in ("TESTAPI", "TESTBPI", "TESTCPI", "TESTDPI"):
        trial = _read(shared_data, f"c3d_org_samples/sample08/{name}.c3d")
        assert np.array_equal(trial.points, ref.points, equal_nan=True), name
        assert np.array_equal(trial.analog, ref.analog), name
    assert ref.points.shape == (450, 26, 3) and ref.analog.shape[1] == 16
    pi = _read(shared_data, "c3d_org_samples/sample01/Eb015pi.c3d")
    assert np.array_equal(pi.points, ref.points, equal_nan=True)


def test_sample02_variants(shared_data: Path) -> None:
    names = ["dec_int", "dec_real", "pc_int", "pc_real", "sgi_int", "sgi_real"]
    trials = {n: _read(shared_data, f"c3d_org_samples/sample02/{n}.c3d") for n in names}
    ref = trials["pc_real"]
    assert ref.points.shape == (89, 36, 3) and ref.analog.shape == (89 * 4, 16)
    assert (ref.point_rate, ref.analog_rate, ref.first_frame) == (50.0, 200.0, 1)
    assert abs(ref.metadata["point_scale"]) == pytest.approx(0.28118, abs=1e-5)
    for n in ("dec_real", "dec_int", "sgi_real"):
        assert np.array_equal(trials[n].points, ref.points, equal_nan=True), n
    for n in ("pc_int", "sgi_int"):
        diff = np.nanmax(np.abs(trials[n].points - ref.points))
        assert diff <= 0.28119, (n, diff)
    assert len(trials["dec_int"].metadata["header_events"]) == 8
    for n in names[1:]:
        assert len(trials[n].metadata["header_events"]) == 9, n


@pytest.mark.parametrize(
    ("name", "frames", "markers", "channels", "rate", "analog_rate", "first", "events"),
    [
        (
            "c3d_org_samples/sample00/Motion Analysis Corporation/Sample_Jump2.c3d",
            264,
            51,
            16,
            120,
            600,
            1,
            4,
        ),
        (
            "c3d_org_samples/sample00/Motion Analysis Corporation/Walk1.c3d",
            151,
            49,
            18,
            60,
            960,
            1,
            8,
        ),
        (
            "c3d_org_samples/sample00/Vicon Motion Systems/pyCGM2 lower limb CGM24 Walking01.c3d",
            493,
            171,
            6,
            100,
            1000,
            63,
            18,
        ),
        ("c3d_org_samples/sample03/gait-pig-nz.c3d", 301, 85, 18, 120, 1800, 300, 7),
        ("c3d_org_samples/sample03/gait-pig.c3d", 142, 77, 30, 50, 800, 1, 9),
        ("c3d_org_samples/sample26/Capture0004.c3d", 453, 18, 16, 240, 240, 389, 0),
        ("c3d_org_samples/sample30/admarche2.c3d", 159, 17, 8, 50, 50, 65, 0),
        (
            "c3d_org_samples/sample35/Mega Electronics Isokinetic EMG Angle Torque Sample File.c3d",
            29,
            0,
            4,
            1,
            1250,
            1,
            0,
        ),
        ("ezc3d_testfiles/Vicon.c3d", 580, 51, 38, 100, 2000, 1, 0),
        ("ezc3d_testfiles/Qualisys.c3d", 340, 55, 69, 200, 2000, 705, 7),
        ("ezc3d_testfiles/BTS.c3d", 675, 22, 44, 100, 1000, 1, 0),
        ("ezc3d_testfiles/Optotrak.c3d", 29, 54, 0, 30, 0, 1, 0),
        ("ezc3d_testfiles/Kistler.c3d", 3969, 0, 16, 60, 600, 1, 0),
        ("ezc3d_testfiles/read_NOTworking2.c3d", 670, 23, 0, 25, 0, 0, 0),
        ("c3d_org_samples/sample27/kyowadengyo.c3d", 152, 11, 24, 60, 60, 33, 0),
    ],
)
def test_stated_values(
    shared_data: Path,
    name: str,
    frames: int,
    markers: int,
    channels: int,
    rate: float,
    analog_rate: float,
    first: int,
    events: int,
) -> None:
    trial = _read(shared_data, name)
    assert trial.points.shape == (frames, markers, 3)
    assert trial.analog.shape[1] == channels
    assert trial.point_rate == pytest.approx(rate)
    assert trial.analog_rate == pytest.approx(analog_rate)
    assert trial.first_frame == first
    assert len(trial.events) == events


def test_vicon_reference_values(shared_data: Path) -> None:
    """ezc3d's own test: first and last values and the sum of all valid coordinates."""
    trial = _read(shared_data, "ezc3d_testfiles/Vicon.c3d")
    assert trial.points[0, 0, 0] == 44.16278839111328
    assert trial.points[-1, 50, 2] == 99.682586669921875
    assert np.nansum(trial.points) == pytest.approx(42506014.918278672, rel=1e-12)
    assert trial.analog.shape == (580 * 20, 38)


def test_units_are_converted_to_mm(shared_data: Path) -> None:
    """IST writes metres with POINT:SCALE -1: values come back in mm."""
    trial = _read(
        shared_data, "c3d_org_samples/sample00/Innovative Sports Training/Gait with EMG.c3d"
    )
    assert trial.metadata["file_units"] == "m"
    span = np.nanmax(trial.points) - np.nanmin(trial.points)
    assert 500 < span < 20000, span


def test_scale_disagreement_is_settled_by_the_marker_distances(shared_data: Path) -> None:
    """MACsample: POINT:SCALE 0.02154, header 0.05511. The header's gives an adult's body.

    newwalk.c3d (same vendor, same folder, a file that follows the manual) is the
    yardstick: its foot (heel-toe) is 168-171 mm, its shoulders 311 mm apart.
    """
    trial = _read(shared_data, "c3d_org_samples/sample06/MACsample.c3d")
    assert trial.metadata["point_scale"] == pytest.approx(0.0551136, abs=1e-6)
    assert any("POINT:SCALE says 0.0215" in note for note in trial.metadata["notes"])

    def distance(t: Trial, a: str, b: str) -> float:
        i, j = t.labels.index(a), t.labels.index(b)
        return float(np.nanmedian(np.linalg.norm(t.points[:, i] - t.points[:, j], axis=1)))

    reference = _read(shared_data, "c3d_org_samples/sample06/newwalk.c3d")
    for a, b, low, high in (("RHEE", "RTOE", 185, 195), ("RSHO", "LSHO", 398, 410)):
        assert low < distance(trial, a, b) < high, (a, b)
        ratio = distance(trial, a, b) / distance(reference, a, b)
        assert 1.0 < ratio < 1.4, (a, b, ratio)  # the parameter's scale would give 0.44-0.51
    shoulder = trial.points[:, trial.labels.index("RSHO"), 2]
    assert 1450 < np.nanmax(shoulder) < 1550  # mm above the floor


def test_simi_all_residuals_invalid(shared_data: Path) -> None:
    trial = _read(shared_data, "c3d_org_samples/sample16/basketball.c3d")
    assert trial.points.shape == (34, 22, 3)
    assert np.isnan(trial.points).all()


def test_optotrak_trusts_the_data_not_the_header(shared_data: Path) -> None:
    trial = _read(shared_data, "ezc3d_testfiles/Optotrak.c3d")
    assert trial.n_frames == 29
    assert any("holds 29" in note for note in trial.metadata["notes"])


@pytest.mark.parametrize(
    "name",
    [
        "c3d_org_samples/sample01/Eb015vr.c3d",
        "c3d_org_samples/sample02/sgi_int.c3d",
        "c3d_org_samples/sample03/gait-pig.c3d",
        "c3d_org_samples/sample00/Codamotion/codamotion_gaitwands_19970212.c3d",
        "c3d_org_samples/sample30/admarche2.c3d",
        "ezc3d_testfiles/Qualisys.c3d",
    ],
)
def test_same_values_as_the_c3d_package_frame_loop(shared_data: Path, name: str) -> None:
    """Our whole-array decoding against the c3d package's per-frame reader."""
    c3d = pytest.importorskip("c3d")
    trial = _read(shared_data, name)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the c3d package's notes on odd metadata
        with open(shared_data / name, "rb") as handle:
            frames = list(c3d.Reader(handle).read_frames())
    pts = np.array([p for _, p, _ in frames])
    factor = 1000.0 if trial.metadata["file_units"] == "m" else 1.0
    valid = pts[:, :, 3] >= 0
    assert np.allclose(trial.points[valid], pts[valid][:, :3] * factor, rtol=1e-6)
    # where we see a gap, so does the c3d package (it also drops out-of-range residual words)
    assert not (np.isnan(trial.points[:, :, 0]) & valid).any()
    if trial.analog.size:
        analog = np.concatenate([a.T for _, _, a in frames])
        assert np.allclose(trial.analog, analog, rtol=1e-6, atol=1e-9)
