"""Suite-wide fixtures: every test must leave no thread, child process or open port behind."""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

SHARED = Path(__file__).resolve().parents[1].parent / "shared"


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


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """The shared data folder beside the project (../shared/data)."""
    path = SHARED / "data"
    if not path.is_dir():
        pytest.skip(f"shared data not found at {path}")
    return path
