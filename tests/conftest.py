"""Suite-wide fixtures: every test must leave no thread, child process or open port behind."""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Callable, Iterator
from importlib.metadata import version
from pathlib import Path
from typing import NoReturn

import pytest

SHARED = Path(__file__).resolve().parents[1].parent / "shared"


def pytest_configure(config: pytest.Config) -> None:
    """Under ``--dist loadgroup`` (make test), refuse a pytest on which pytest-xdist's
    grouping has no effect: the end-to-end modules' session recordings would be made
    once per worker, at the same time (twice the time, and two LSL outlets of one name).
    pytest 9.2 no longer reads the field where pytest-xdist 3.8 marks a test's group
    (pytest-dev/pytest-xdist#1386); pyproject.toml keeps pytest below 9.2."""
    if config.getoption("dist", default="no") != "loadgroup":
        return
    xdist = version("pytest-xdist")
    if _release(pytest.__version__) >= (9, 2) and _release(xdist) <= (3, 8):
        raise pytest.UsageError(
            f"--dist loadgroup does not group tests with pytest {pytest.__version__} and "
            f"pytest-xdist {xdist} (pytest-xdist#1386): install the pytest pyproject.toml "
            "asks for (make .venv/.installed-stamp)"
        )


def _release(text: str) -> tuple[int, ...]:
    """(major, minor) of a version string."""
    parts = [int("".join(ch for ch in p if ch.isdigit()) or 0) for p in text.split(".")[:2]]
    return tuple(parts)


def _open_fds() -> dict[int, str]:
    """File descriptors of this process that are sockets, ttys or ptys."""
    found: dict[int, str] = {}
    fd_dir = Path("/proc/self/fd")
    for entry in fd_dir.iterdir():
        try:
            target = os.readlink(entry)
        except OSError:
            continue
        if target.startswith(("socket:", "/dev/pts/", "/dev/ptmx", "/dev/tty")):
            found[int(entry.name)] = target
    return found


def _children() -> set[int]:
    """Live child processes of this process."""
    pid = os.getpid()
    kids: set[int] = set()
    for task in Path(f"/proc/{pid}/task").iterdir():
        try:
            text = (task / "children").read_text()
        except OSError:
            continue
        kids.update(int(p) for p in text.split())
    return kids


@pytest.fixture(autouse=True)
def no_leaks() -> Iterator[None]:
    """Fail a test that leaves a thread, a child process or an open port behind."""
    threads_before = set(threading.enumerate())
    fds_before = _open_fds()
    kids_before = _children()
    yield
    deadline = time.monotonic() + 2.0
    while True:
        threads = [t for t in threading.enumerate() if t not in threads_before and t.is_alive()]
        fds = {fd: t for fd, t in _open_fds().items() if fds_before.get(fd) != t}
        kids = _children() - kids_before
        if not (threads or fds or kids) or time.monotonic() > deadline:
            break
        time.sleep(0.02)
    problems = []
    if threads:
        problems.append(f"threads left running: {[t.name for t in threads]}")
    if fds:
        problems.append(f"ports left open: {sorted(fds.values())}")
    if kids:
        problems.append(f"child processes left running: {sorted(kids)}")
    if problems:
        pytest.fail("; ".join(problems), pytrace=False)


#: Simulators stand in for devices, which have processors of their own: their serving
#: threads run at a higher priority than the suite's other work where the system allows
#: (simulators/priority.py), so two busy workers on two cores do not make them late.
#: Set before any test starts one, in this process and the ``spotlab sim`` children.
os.environ.setdefault("SPOTLAB_SIM_NICE", "-10")

#: The reference data (../shared/data, or $SPOTLAB_SHARED_DATA where it lives elsewhere).
SHARED_DATA = Path(os.environ.get("SPOTLAB_SHARED_DATA") or SHARED / "data")


def in_ci() -> bool:
    """True under continuous integration (``CI`` set to true, as CI services do)."""
    return os.environ.get("CI", "").strip().lower() in ("1", "true", "yes")


def missing_reference(what: str) -> NoReturn:
    """Skip a reference test whose data is missing, but fail it under CI.

    A reference test that skips there is a test that silently stopped running.
    """
    if in_ci():
        pytest.fail(f"{what} not found: reference tests must run in CI", pytrace=False)
    pytest.skip(f"{what} not found")


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """The shared reference data folder (../shared/data); fails under CI when missing."""
    if not SHARED_DATA.is_dir():
        missing_reference(f"shared data folder {SHARED_DATA}")
    return SHARED_DATA


@pytest.fixture(scope="session")
def shared_file(shared_data: Path) -> Callable[[str], Path]:
    """``shared_file("folder/name")``: a file of the shared data (fails under CI if missing)."""

    def get(relative: str) -> Path:
        path = shared_data / relative
        if not path.exists():
            missing_reference(str(path))
        return path

    return get
