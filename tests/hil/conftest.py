"""Fixtures of the end-to-end tests; the helpers they use are in ``_e2e.py``."""

from __future__ import annotations

from pathlib import Path

import pytest
from _e2e import record_args, run_cli, sim_pty


@pytest.fixture(scope="session")
def short_recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A real 1.5 s journal recorded through a pty (simulator and recorder processes, both
    ended before the fixture returns), made once for the run."""
    folder = tmp_path_factory.mktemp("short-recording")
    journal = folder / "run.spj"
    with sim_pty(folder, seed=5) as sim:
        result = run_cli(*record_args(sim.path, journal, 1.5), timeout=60)
        assert result.returncode == 0, result.stderr
    return journal
