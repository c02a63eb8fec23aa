"""Bad ``spotlab sim wsx`` options: one ``spotlab: error:`` line each, nothing served."""

from __future__ import annotations

from pathlib import Path

import pytest

from spotlab.console.cli import main

ERROR = "spotlab: error:"


@pytest.mark.parametrize(
    ("args", "says"),
    [
        (
            ["--markers", "24", "--marker-rate", "4600", "--rate", "200"],
            "marker rate / (markers + 2)",
        ),
        (["--marker-rate", "5000"], "--marker-rate must be 1500 to 4600 Hz"),
        (["--sensors", "9"], "--sensors must be 1 to 8"),
        (["--faults", "melt@1"], "fault 'melt@1'"),
        (["--truth", "T.csv"], "the wsx truth is an .npz file"),
    ],
)
def test_bad_simulator_options_are_one_line(
    args: list[str], says: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["sim", "wsx", *[str(tmp_path / a) if a.endswith(".csv") else a for a in args]]
    assert main(argv) != 0
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith(ERROR) and says in lines[0], err
