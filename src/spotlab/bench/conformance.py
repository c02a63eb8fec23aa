"""Run a family's conformance suite against one port, in this process, test by test.

The suites are the ones ``pytest tests/conformance --hw FAMILY=PORT`` runs
(:mod:`spotlab.testing.family_conformance`, ``qualisys_conformance``,
``natnet_conformance``). A small test module naming the family's suite is written
to a scratch folder and run by ``pytest.main`` with ``--hw FAMILY=PORT``; a plugin
keeps every test's outcome and, for a failure, the reason pytest gave (the
assertion with its values: the suites' modules are rewritten by pytest's assertion
rewriting). pytest's own terminal output is kept, not printed.
"""

from __future__ import annotations

import contextlib
import io
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from spotlab.core.errors import ConfigurationError

#: Family -> (module, class) of its suite.
SUITES: dict[str, tuple[str, str]] = {
    "selspot": ("spotlab.testing.family_conformance", "SelspotConformance"),
    "timer": ("spotlab.testing.family_conformance", "TimerConformance"),
    "centroid": ("spotlab.testing.family_conformance", "CentroidConformance"),
    "coda": ("spotlab.testing.family_conformance", "CodaConformance"),
    "qualisys": ("spotlab.testing.qualisys_conformance", "QualisysConformance"),
    "natnet": ("spotlab.testing.natnet_conformance", "NatNetConformance"),
    "wsx": ("spotlab.testing.wsx_conformance", "WsxConformance"),
}

#: Extra fixtures a suite needs from its test module (the NatNet suite's address).
_FIXTURES: dict[str, str] = {
    "natnet": """

@pytest.fixture
def natnet_address(request: pytest.FixtureRequest) -> str:
    return hardware_ports(request.config)["natnet"]
""",
    "wsx": """

@pytest.fixture
def wsx_port(request: pytest.FixtureRequest) -> str:
    port = hardware_ports(request.config)["wsx"]
    return port if ":" in port else f"usb:{port}"
""",
}

_CONFTEST = """import pytest

pytest.register_assert_rewrite("spotlab.testing")
"""


@dataclass(frozen=True)
class TestOutcome:
    """One conformance test.

    Attributes
    ----------
    name : str
        The test's name (with its parameter, if any).
    outcome : str
        ``"passed"``, ``"failed"`` or ``"skipped"``.
    reason : str
        Why it failed or was skipped (empty when it passed).
    seconds : float
        Time it took (setup, call and teardown).
    """

    name: str
    outcome: str
    reason: str
    seconds: float


def _module_text(family: str) -> str:
    module, cls = SUITES[family]
    lines = [
        "import pytest",
        "",
        "from spotlab.testing.pytest_plugin import hardware_ports",
        f"from {module} import {cls}",
        "",
        "",
        f"class TestBench({cls}):",
        f'    """The {family} suite against the ``--hw`` port."""',
    ]
    return "\n".join(lines) + _FIXTURES.get(family, "") + "\n"


def _reason(report: Any) -> str:
    """The first ``E ...`` line(s) of a failure (the exception and its message), else the
    report's last line."""
    text = str(getattr(report, "longreprtext", "") or report.longrepr or "")
    if report.skipped and isinstance(report.longrepr, tuple):
        return str(report.longrepr[2]).removeprefix("Skipped: ")
    found = [line[1:].strip() for line in text.splitlines() if line.startswith("E ")]
    if found:  # the exception and its message; pytest's explanation of the values follows
        first = found[0] if len(found[0]) > 40 or len(found) == 1 else " ".join(found[:2])
        return first[:300]
    lines = [line for line in text.splitlines() if line.strip()]
    return lines[-1][:500] if lines else "failed"


class _Collector:
    """pytest plugin: every test's outcome, in order."""

    def __init__(self) -> None:
        self.tests: dict[str, dict[str, Any]] = {}

    def pytest_runtest_logreport(self, report: Any) -> None:
        name = str(report.nodeid).rpartition("::")[2]
        entry = self.tests.setdefault(name, {"outcome": "passed", "reason": "", "seconds": 0.0})
        entry["seconds"] += float(report.duration)
        if report.failed and entry["outcome"] != "failed":
            entry["outcome"] = "failed"
            entry["reason"] = (f"({report.when}) " if report.when != "call" else "") + _reason(
                report
            )
        elif report.skipped and entry["outcome"] == "passed":
            entry["outcome"] = "skipped"
            entry["reason"] = _reason(report)

    def pytest_collectreport(self, report: Any) -> None:
        if report.failed:
            self.tests["<collection>"] = {
                "outcome": "failed",
                "reason": _reason(report),
                "seconds": 0.0,
            }


def run_suite(family: str, port: str, select: str | None = None) -> tuple[list[TestOutcome], str]:
    """Run the conformance suite of ``family`` against ``port``.

    Parameters
    ----------
    family : str
        A family of :data:`SUITES`.
    port : str
        What ``--hw FAMILY=PORT`` would be given: a device path, pyserial URL or
        ``HOST:PORT``.
    select : str, optional
        A pytest ``-k`` expression choosing some of the tests.

    Returns
    -------
    outcomes : list of TestOutcome
        Every test, in the order they ran (parametrised ones once per parameter).
    log : str
        pytest's terminal output.

    Raises
    ------
    ConfigurationError
        If the family has no suite or pytest is not installed.
    """
    if family not in SUITES:
        raise ConfigurationError(
            f"no conformance suite for {family!r} devices (bench knows {', '.join(SUITES)})"
        )
    try:
        import pytest
    except ImportError:  # pragma: no cover - pytest comes with spotlab's test tools
        raise ConfigurationError("spotlab bench needs pytest (pip install pytest)") from None
    collector = _Collector()
    out = io.StringIO()
    with tempfile.TemporaryDirectory(prefix="spotlab-bench-") as tmp:
        folder = Path(tmp)
        (folder / "pytest.ini").write_text("[pytest]\n", encoding="utf-8")
        (folder / "conftest.py").write_text(_CONFTEST, encoding="utf-8")
        module = folder / f"test_bench_{family}.py"
        module.write_text(_module_text(family), encoding="utf-8")
        args = [
            str(module),
            "--hw",
            f"{family}={port}",
            "-c",
            str(folder / "pytest.ini"),
            "--rootdir",
            str(folder),
            "-p",
            "no:cacheprovider",
            "-q",
        ]
        if select:
            args += ["-k", select]
        with contextlib.redirect_stdout(out):
            code = pytest.main(args, plugins=[collector])
    if code == pytest.ExitCode.INTERRUPTED:  # pytest caught the Ctrl-C: pass it on
        raise KeyboardInterrupt
    outcomes = [
        TestOutcome(name, e["outcome"], e["reason"], round(e["seconds"], 3))
        for name, e in collector.tests.items()
    ]
    return outcomes, out.getvalue()


__all__ = ["SUITES", "TestOutcome", "run_suite"]
