"""Bad scanner input gives one clear line (issue 18): a marker code outside the colour
table, a configuration the line's bandwidth refuses, a unit that reports another
geometry than asked for (the recording's), an output mode that does not exist."""

from __future__ import annotations

from pathlib import Path

import pytest

from spotlab.console.cli import main

ERROR = "spotlab: error:"


@pytest.mark.parametrize(
    ("device", "says"),
    [
        ("coda=sim://coda,markers=RO+XX", "marker code 'XX' is not in the colour table"),
        ("coda=sim://coda,markers=56,rate=100,baud=921600", "use baud=2000000"),
        ("coda=sim://coda?base_mm=1200,base=1000", "mirror base of 1200 mm, not the 1000 mm"),
        ("coda=sim://coda,out=2D", "mode must be one of"),
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
