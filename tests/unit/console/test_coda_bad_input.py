"""Bad scanner input gives one clear line (issue 18): a marker code outside the colour
table, a configuration the line's bandwidth refuses, a unit that reports another
geometry than asked for (the recording's) or than the recording holds (at reconstruct, at
a reconnection), an output mode that does not exist."""

from __future__ import annotations

from pathlib import Path

import pytest

from spotlab.console.cli import main
from spotlab.core.errors import ConfigurationError
from spotlab.drivers.coda import CodaDriver
from spotlab.drivers.coda.protocol import parse_version
from spotlab.drivers.mcs1.commands import Reply
from spotlab.processing.errors import InputError
from spotlab.processing.scanner_trajectories import check_geometry

ERROR = "spotlab: error:"


@pytest.mark.parametrize(
    ("device", "says"),
    [
        ("coda=sim://coda,markers=RO+XX", "marker code 'XX' is not in the colour table"),
        ("coda=sim://coda,markers=56,rate=100,baud=921600", "use baud=2000000"),
        ("coda=sim://coda?base_mm=1200,base=1000", "mirror base of 1200 mm, not the 1000 mm"),
        ("coda=sim://coda,out=2D", "mode must be one of"),
        ("coda=sim://coda,markers=28,rate=400,out=BOTH", "in BOTH mode at 400 Hz need 3.44"),
    ],
)
def test_bad_scanner_input_is_one_line(
    device: str, says: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code = main(["record", "--device", device, "--seconds", "1", "--out", str(tmp_path / "r.spj")])
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.strip()]
    assert code != 0 and "Traceback" not in err
    assert len(lines) == 1 and lines[0].startswith(ERROR) and says in lines[0], err


def test_a_unit_coming_back_with_another_geometry_is_refused() -> None:
    driver = CodaDriver("sim://coda")
    first = parse_version("CSX 1.0 SIM00031 1000000 16000 40000")
    other = parse_version("CSX 1.0 SIM00031 1200000 16000 40000")
    reply = Reply("data", first.text, None, b"")
    driver._check_version(first, reply)
    driver._check_version(first, reply)  # the same unit after a reset: fine
    with pytest.raises(ConfigurationError) as exc:
        driver._check_version(other, Reply("data", other.text, None, b""))
    message = str(exc.value)
    assert "\n" not in message and "1200 mm" in message and "SIM00031 with 1000 mm" in message


@pytest.mark.parametrize(
    ("geometries", "config", "says"),
    [
        (
            [{"base_mm": 1000.0}, {"base_mm": 1200.0}],
            {},
            "(?), later a mirror base of 1200",
        ),
        ([{"base_mm": 1200.0}], {"base_um": 1000000}, "asked for a mirror base of 1000 mm"),
    ],
)
def test_a_recording_whose_unit_reported_another_geometry_is_refused(
    geometries: list[dict[str, float]], config: dict[str, int], says: str
) -> None:
    with pytest.raises(InputError) as exc:
        check_geometry(Path("r.spj"), "coda", geometries, {"config": config})  # type: ignore[arg-type]
    assert says in str(exc.value) and "\n" not in str(exc.value)
