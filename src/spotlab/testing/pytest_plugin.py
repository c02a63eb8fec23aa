"""pytest plugin: ``--hw FAMILY=PORT`` runs a family's conformance suite on real hardware;
``--hil SCENARIOS`` runs hardware-in-the-loop scenario files as tests.

Registered through the ``pytest11`` entry point, so it is active in any pytest
run where spotlab is installed. Without ``--hw`` the conformance suites run
against the simulators only. ``--hil`` takes a scenario file, a folder of them or
the name of a shipped scenario (``spotlab hil list``), once or more; the run then
collects those scenarios only (one test each, failed with every criterion that did
not hold; the report folder is named in the failure).
"""

from __future__ import annotations

import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from spotlab.core.errors import ConfigurationError


def pytest_addoption(parser: pytest.Parser) -> None:
    group = parser.getgroup("spotlab")
    group.addoption(
        "--hw",
        action="append",
        default=[],
        metavar="FAMILY=PORT",
        help="run the conformance suite of FAMILY against the real device at PORT "
        "(a device path or pyserial URL); may be given once per family",
    )
    group.addoption(
        "--hil",
        action="append",
        default=[],
        metavar="SCENARIOS",
        help="run these scenario files (a file, a folder of *.toml or a shipped scenario's "
        "name) as tests, and nothing else; repeat for several",
    )


def hardware_ports(config: pytest.Config) -> dict[str, str]:
    """The ``--hw`` options as ``{family: port}``.

    Raises
    ------
    ConfigurationError
        If an option is not of the form ``FAMILY=PORT``.
    """
    ports: dict[str, str] = {}
    for item in config.getoption("--hw"):
        family, sep, port = str(item).partition("=")
        if not sep or not family or not port:
            raise ConfigurationError(f"--hw takes FAMILY=PORT, got {item!r}")
        ports[family] = port
    return ports


def hil_paths(config: pytest.Config) -> list[Path]:
    """The scenario files the ``--hil`` options name (folders expanded, names resolved)."""
    from spotlab.hil.catalog import resolve

    found: list[Path] = []
    for item in config.getoption("--hil"):
        path = Path(str(item))
        if path.is_dir():
            found += sorted(path.glob("*.toml"))
        else:
            found.append(resolve(str(item)))
    return found


def pytest_configure(config: pytest.Config) -> None:
    if config.getoption("--hil", default=None):
        # Collect the scenarios only: they are the run's arguments.
        config.args = [str(p) for p in hil_paths(config)]


def pytest_collect_file(file_path: Path, parent: pytest.Collector) -> pytest.Collector | None:
    if not parent.config.getoption("--hil", default=None) or file_path.suffix != ".toml":
        return None
    wanted = {p.resolve() for p in hil_paths(parent.config)}
    if file_path.resolve() not in wanted:
        return None
    found: pytest.Collector = ScenarioFile.from_parent(parent, path=file_path)
    return found


class ScenarioFile(pytest.File):
    """A scenario file: one test."""

    def collect(self) -> Iterator[pytest.Item]:
        item = ScenarioItem.from_parent(self, name=self.path.stem)
        if self.config.pluginmanager.hasplugin("timeout"):
            # At collection: pytest-timeout reads the marker before the item's own setup.
            item.add_marker(pytest.mark.timeout(_time_limit(self.path)))
        yield item


def _time_limit(path: Path) -> float:
    """Seconds a scenario may take: 3 times its duration and 4 minutes, and 10 minutes
    more for the lab's preparation (calibration, model: recordings and calibrations)."""
    import tomllib

    from spotlab.hil.catalog import describe

    _, duration, _ = describe(path)
    steps = tomllib.loads(path.read_text()).get("processing", {}).get("steps", [])
    extra = 600 if {"calibration", "model"} & set(steps) else 0
    return float(duration * 3 + 240 + extra)


class ScenarioFailed(Exception):
    """The scenario ran and a criterion did not hold (or the run failed)."""


class ScenarioItem(pytest.Item):
    """Runs :func:`spotlab.hil.runner.run_scenario` on its file."""

    def runtest(self) -> None:
        from spotlab.hil.runner import run_scenario
        from spotlab.hil.scenario import load_scenario

        scenario = load_scenario(self.path)
        folder = Path(tempfile.mkdtemp(prefix=f"spotlab-hil-{self.path.stem}-"))
        summary = run_scenario(scenario, folder)
        self.user_properties.append(("report", str(folder / "report.html")))
        if summary["verdict"] != "pass":
            lines = [f"report: {folder / 'report.html'}"]
            if summary["problem"]:
                lines.append(f"problem: {summary['problem']}")
            lines += [f"{c['criterion']}: got {c['value']}" for c in summary["criteria"]
                      if not c["passed"]]  # fmt: skip
            raise ScenarioFailed("\n".join(lines))

    def repr_failure(self, excinfo: Any, style: Any = None) -> str:
        if isinstance(excinfo.value, ScenarioFailed | ConfigurationError):
            return str(excinfo.value)
        return str(super().repr_failure(excinfo))

    def reportinfo(self) -> tuple[Path, int, str]:
        return self.path, 0, f"scenario {self.path.name}"
