"""Third-party libraries spotlab loads print nothing on the user's terminal (issue 12 §4):
liblsl's info log and depthai's warnings are turned down where spotlab imports them."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest


def _stderr_of(code: str, tmp_path: Path) -> str:
    env = {k: v for k, v in os.environ.items() if k not in ("LSLAPICFG", "DEPTHAI_LEVEL")}
    env["HOME"] = str(tmp_path)  # no ~/lsl_api/lsl_api.cfg
    result = subprocess.run(
        [sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True, text=True,
        timeout=120,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    return result.stderr


@pytest.mark.timeout(150)
def test_liblsl_logs_nothing(tmp_path: Path) -> None:
    pytest.importorskip("pylsl", reason="the lsl extra is not installed")
    code = (
        "from spotlab.acquisition.lsl._pylsl import pylsl_module\n"
        "pylsl = pylsl_module()\n"
        "info = pylsl.StreamInfo('quiet-test', 'Mocap', 1, 100, 'float32', 'quiet-test')\n"
        "outlet = pylsl.StreamOutlet(info)\n"
    )
    assert _stderr_of(code, tmp_path) == ""


@pytest.mark.timeout(150)
def test_a_liblsl_config_file_is_respected(tmp_path: Path) -> None:
    """With a configuration file of the user's, spotlab leaves liblsl's log alone."""
    pytest.importorskip("pylsl", reason="the lsl extra is not installed")
    (tmp_path / "lsl_api.cfg").write_text("[log]\nlevel = 0\n")
    code = (
        "from spotlab.acquisition.lsl._pylsl import pylsl_module\n"
        "pylsl = pylsl_module()\n"
        "info = pylsl.StreamInfo('quiet-test', 'Mocap', 1, 100, 'float32', 'quiet-test')\n"
    )
    assert "INFO" in _stderr_of(code, tmp_path)


@pytest.mark.timeout(150)
def test_depthai_warns_nothing_at_import(tmp_path: Path) -> None:
    pytest.importorskip("depthai", reason="the oak extra is not installed")
    code = "from spotlab.drivers.oak.depthai_camera import depthai_module\ndepthai_module()\n"
    assert "[depthai]" not in _stderr_of(code, tmp_path)
