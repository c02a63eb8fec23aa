"""Files from other labs: what they do that the manual does not, read as ezc3d reads them.

Every comparison runs ezc3d in a child process (ezc3d_child.py). Reference data:
shared/data SOURCES.md §1 (c3d.org samples 07, 10, 18, 33).
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
from ezc3d_child import ezc3d_dump

from spotlab.io import read_c3d, write_c3d
from spotlab.io.c3d_files import read_c3d_parameters

SAMPLES = "c3d_org_samples"
FORCE_PLATE_FILES = ["sample10/TYPE-2.C3D", "sample10/TYPE-3.c3d", "sample10/TYPE-4.C3D"]
FP_KEYS = ("TYPE", "USED", "CORNERS", "ORIGIN", "CHANNEL", "CAL_MATRIX", "ZERO")


def test_sample07_offsets_of_an_unsigned_converter(shared_data: Path, tmp_path: Path) -> None:
    """ANALOG:OFFSET stored as -32768 is the midpoint 32768 of an unsigned 16-bit converter."""
    path = shared_data / SAMPLES / "sample07/16bitanalog.c3d"
    trial = read_c3d(path)
    ez = ezc3d_dump(path, tmp_path / "ez.npz")
    assert trial.analog.shape == ez["analog"].shape == (237 * 10, 40)
    stored = read_c3d_parameters(path)[1].get("ANALOG:OFFSET")
    assert stored is not None
    negative = stored.words(signed=True) < 0
    assert negative.sum() == 7  # channels 33-39
    # all 40 channels as ezc3d gives them (before: 65536 too high on those 7)
    assert np.allclose(trial.analog, ez["analog"], rtol=1e-6, atol=1e-9)
    assert np.abs(trial.analog[:, negative]).max() < 100.0  # raw counts (scale 1): 43 at most
    assert any("unsigned" in note for note in trial.metadata["notes"])


def test_sample07_signed_offsets_stay_signed_elsewhere(shared_data: Path) -> None:
    """The same offsets in a file whose samples are signed keep their sign."""
    trial = read_c3d(shared_data / SAMPLES / "sample02/pc_int.c3d")
    assert not any("unsigned" in note for note in trial.metadata["notes"])


def test_sample33_repeated_parameters_later_record_wins(shared_data: Path, tmp_path: Path) -> None:
    """Vicon Nexus repeats PROCESSING parameters up to 30 times; the last record wins (ezc3d)."""
    path = shared_data / SAMPLES / "sample33/bigparlove.c3d"
    trial = read_c3d(path)
    params = trial.metadata["c3d_parameters"]
    keys = ("PROCESSING:MARKERDIAMETER", "PROCESSING:RLINE1OFFSETXROT", "POINT:DATA_START")
    ez = ezc3d_dump(path, tmp_path / "ez.npz", keys)
    assert trial.points.shape == ez["points"].shape == (323, 205, 3)
    assert np.array_equal(trial.points, ez["points"], equal_nan=True)
    assert np.allclose(trial.analog, ez["analog"], rtol=1e-6, atol=1e-9)
    assert params.repeated["PROCESSING:MARKERDIAMETER"] == 30
    assert len(params.repeated) == 113
    # the 30 records of RLINE1OFFSETXROT hold 5 different values; the last is 2.96749
    value = params.get("PROCESSING:RLINE1OFFSETXROT").floats()
    assert value == pytest.approx(ez["params"]["PROCESSING:RLINE1OFFSETXROT"], abs=1e-6)
    assert value[0] == pytest.approx(2.96749, abs=1e-5)
    assert params.get("POINT:DATA_START").count() == 188  # > 127: unsigned
    # every PROCESSING parameter ezc3d has, we have with its value
    assert set(ez["groups"]["PROCESSING"]) == set(params.groups["PROCESSING"])
    notes = " ".join(trial.metadata["notes"])
    assert "113 parameter(s) given more than once" in notes and "group PROCESSING" in notes


def test_sample18_damaged_parameter_section_is_read_up_to_the_damage(shared_data: Path) -> None:
    """The last "group" record has a name of NULs and a pointer of -1: stop there, keep the rest.

    ezc3d refuses the file (and crashes with ignore_bad_formatting), the c3d package too.
    """
    trial = read_c3d(shared_data / SAMPLES / "sample18/bad_parameter_section.c3d")
    params = trial.metadata["c3d_parameters"]
    assert list(params.groups) == ["POINT", "ANALOG", "FORCE_PLATFORM", "EMG", "EVENT"]
    assert trial.points.shape == (332, 45, 3) and trial.analog.shape == (3320, 32)
    assert trial.point_rate == 120.0
    assert any("damaged record at byte 5259" in note for note in trial.metadata["notes"])
    seen = trial.points[np.isfinite(trial.points[:, :, 0])]
    assert np.abs(seen).max() < 3000.0  # millimetres in a gait lab


def _fp_params(path: Path) -> dict[str, np.ndarray]:
    params = read_c3d_parameters(path)[1]
    out = {}
    for key in FP_KEYS:
        param = params.get(f"FORCE_PLATFORM:{key}")
        if param is not None:  # TYPE-3.c3d has no CAL_MATRIX
            out[key] = param.floats()
    assert {"TYPE", "CORNERS", "ORIGIN", "CHANNEL"} <= set(out)
    return out


@pytest.mark.parametrize("name", FORCE_PLATE_FILES)
def test_force_plates_survive_our_writer(shared_data: Path, tmp_path: Path, name: str) -> None:
    """FORCE_PLATFORM (type, corners, origin, channels, CAL_MATRIX) is written back as read,
    and ezc3d computes the same forces, moments and centres of pressure from our copy."""
    source = shared_data / SAMPLES / name
    copy = tmp_path / "copy.c3d"
    write_c3d(copy, read_c3d(source))
    assert _fp_params(copy).keys() == _fp_params(source).keys()
    for key, value in _fp_params(source).items():
        assert np.array_equal(_fp_params(copy)[key], value), key
    # ezc3d: same parameters, same force-plate outputs (analog rounded to float32)
    keys = tuple(f"FORCE_PLATFORM:{k}" for k in FP_KEYS)
    ez_src = ezc3d_dump(source, tmp_path / "a.npz", keys)
    ez_out = ezc3d_dump(copy, tmp_path / "b.npz", keys)
    for key in keys:
        if ez_src["params"][key] is None:
            assert ez_out["params"][key] is None, key
        else:
            assert np.allclose(ez_out["params"][key], ez_src["params"][key], rtol=1e-7), key
    forces_src = _ezc3d_forces(source)
    forces_out = _ezc3d_forces(copy)
    assert forces_src.shape == forces_out.shape and forces_src.size > 0
    scale = np.nanmax(np.abs(forces_src))
    # measured: 3.0e-8, 3.9e-8, 2.1e-9 of the largest value (analog rounded to float32)
    assert np.nanmax(np.abs(forces_out - forces_src)) < 2e-7 * scale
    # the c3d package reads the group too
    c3d = pytest.importorskip("c3d")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with open(copy, "rb") as handle:
            reader = c3d.Reader(handle)
            corners = np.asarray(reader.get("FORCE_PLATFORM:CORNERS").float_array).ravel()
            origin = np.asarray(reader.get("FORCE_PLATFORM:ORIGIN").float_array).ravel()
    assert np.array_equal(corners, _fp_params(source)["CORNERS"])
    assert np.array_equal(origin, _fp_params(source)["ORIGIN"])


_FORCES = """
import sys, numpy as np, ezc3d
c = ezc3d.c3d(sys.argv[1], extract_forceplat_data=True)
np.save(sys.argv[2], np.stack([np.concatenate([p["force"], p["moment"], p["center_of_pressure"]])
                               for p in c["data"]["platform"]]))
"""


def _ezc3d_forces(path: Path) -> np.ndarray:
    """ezc3d's force, moment and centre of pressure of every plate, (plates, 9, samples)."""
    import subprocess
    import sys

    out = path.with_suffix(".forces.npy")
    done = subprocess.run(
        [sys.executable, "-c", _FORCES, str(path), str(out)],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert done.returncode == 0, done.stderr[-800:]
    return np.load(out)


def test_type4_cal_matrix_against_c3d_orgs_spreadsheet(shared_data: Path, tmp_path: Path) -> None:
    """CAL_MATRIX of TYPE-4.C3D written by us against c3d.org's TYPE-4.xls (7 March 2003).

    The file (2 June 2002) stores the matrix to 3 decimals; the spreadsheet's has more.
    They agree to that rounding everywhere; one element (row Fz, column Mz) has the
    opposite sign in the file: 4.609 against -4.6095.
    """
    xlrd = pytest.importorskip("xlrd")
    copy = tmp_path / "type4.c3d"
    write_c3d(copy, read_c3d(shared_data / SAMPLES / "sample10/TYPE-4.C3D"))
    stored = _fp_params(copy)["CAL_MATRIX"].reshape(6, 6)  # row i = file's column i
    sheet = xlrd.open_workbook(str(shared_data / SAMPLES / "sample10/TYPE-4.xls")).sheet_by_index(0)
    reference = np.array([[sheet.cell_value(r, c) for c in range(9, 15)] for r in range(14, 20)])
    assert np.abs(np.abs(stored) - np.abs(reference)).max() <= 5.1e-4
    flipped = np.argwhere(np.sign(stored) * np.sign(reference) < 0)
    assert flipped.tolist() == [[2, 5]]
