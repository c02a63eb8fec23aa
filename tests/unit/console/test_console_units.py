"""The console's parts without a console process: trial store and names, link health,
the clock column, gap counts, the page's files, device settings changed from the page."""

from __future__ import annotations

import fnmatch
import tomllib
from pathlib import Path

import numpy as np
import pytest

from spotlab.console.web.lab_setup import plan_lab, settings_of, with_rate, with_settings
from spotlab.console.web.trials import TrialInfo, TrialStore, check_name
from spotlab.processing.errors import InputError


def test_the_page_ships_as_package_data() -> None:
    """Every file of static/ is matched by pyproject's package-data (no CDN, no fetch)."""
    root = Path(__file__).resolve().parents[3]
    config = tomllib.loads((root / "pyproject.toml").read_text())
    patterns = config["tool"]["setuptools"]["package-data"]["spotlab.console.web"]
    static = root / "src" / "spotlab" / "console" / "web" / "static"
    files = sorted(p.relative_to(static.parent).as_posix() for p in static.iterdir())
    assert files == ["static/console.css", "static/console.js", "static/index.html"]
    assert all(any(fnmatch.fnmatch(f, pat) for pat in patterns) for f in files)
    for f in files:
        assert "http://" not in (static.parent / f).read_text().replace("http://127", "")
        assert "https://" not in (static.parent / f).read_text()


# ---- the trial store ---------------------------------------------------------------
@pytest.mark.parametrize("bad", ["", "..", "../x", "a/b", "a.b", "x" * 65, "é", " a", None, 3])
def test_names_are_checked(bad: object) -> None:
    with pytest.raises(InputError, match="not valid"):
        check_name("trial", bad)


def test_store_keeps_trials_inside_the_data_folder(tmp_path: Path) -> None:
    store = TrialStore(tmp_path / "data")
    assert store.journal("S01", "walk", "t-1_a") == store.root / "S01" / "walk" / "t-1_a.spj"
    for tid in ("..", "S01.walk", "S01.walk.t1.x", "S01.%2e%2e.t1", "S01..t1"):
        with pytest.raises(InputError):
            store.parse_id(tid)
    with pytest.raises(InputError, match="outside"):
        store.resolve("..", "etc")
    info = TrialInfo("S01", "walk", "t1", notes="first", frames={"a": 3})
    store.save(info)
    assert store.load("S01.walk.t1") == info
    assert [t.id for t in store.all()] == ["S01.walk.t1"]
    (store.root / "S01" / "walk" / "bad name.json").write_text("{}")  # not a trial name
    assert [t.id for t in store.all()] == ["S01.walk.t1"]
    with pytest.raises(InputError, match="no trial"):
        store.load("S01.walk.t2")


def test_link_health_counts_per_second_and_restarts_with_a_session() -> None:
    from spotlab.console.web.link_health import LinkHealth

    rows = [{"name": "a", "frames": 0, "lost_frames": 0, "crc_errors": 0}]
    health = LinkHealth(lambda: [dict(r) for r in rows])
    for t, (frames, lost, crc) in enumerate([(0, 0, 0), (100, 1, 0), (200, 1, 2), (50, 0, 0)]):
        rows[0].update(frames=frames, lost_frames=lost, crc_errors=crc)
        health.sample(now=float(t))
    got = health.snapshot()["devices"]["a"]
    # the first read is the baseline; a counter that went down is a new session's
    assert got == {
        "t": [1.0, 2.0, 3.0],
        "frames": [100, 100, 50],
        "lost": [1, 0, 0],
        "crc": [0, 2, 0],
    }


def test_the_clock_offset_is_the_session_clock_models() -> None:
    """Offset: session time minus device time by the arrival fit; drift from its rate."""
    from spotlab.console.web.live_view import StreamClock

    t0_ns = 5_000_000_000
    clock = StreamClock(1000.0, t0_ns)  # a 1 kHz device counter
    assert clock.offset_s is None and clock.drift_ppm is None
    rng = np.random.default_rng(0)
    for k in range(1000):  # 10 s at 100 Hz; its zero 2.5 s into the session, 100 ppm fast
        tick = 123_000 + 10 * k
        session_s = 2.5 + tick / 1000.0 / (1 + 100e-6) + 0.002 + 0.0005 * rng.random()
        clock.update(tick, t0_ns + int(session_s * 1e9))
    offset, drift = clock.offset_s, clock.drift_ppm
    assert offset is not None and drift is not None
    # at the last tick (133 s of device time) 100 ppm is 13.3 ms; plus the mean delay
    assert abs(offset - (2.5 + 0.00225 - 133.0 * 100e-6 / (1 + 100e-6))) < 0.0005, offset
    assert abs(drift - 100.0) < 30.0, drift


def test_gap_counts_of_trajectories() -> None:
    from spotlab.console.web.processing_jobs import gap_counts

    nan = np.nan
    x = np.array([[1, nan, 1], [nan, nan, 1], [nan, nan, nan], [1, nan, 1], [nan, nan, 1]])
    points = np.repeat(x[:, :, None], 3, axis=2)  # (F=5, M=3, 3)
    # marker 0: one gap of 2 frames (the trailing miss is not a gap); marker 2: one of 1
    assert gap_counts(points) == {"gaps": 2, "longest_gap_frames": 2, "markers_never_seen": 1}


def test_settings_set_from_the_page_are_checked_as_a_lab_files(tmp_path: Path) -> None:
    plan = plan_lab(None, True, tmp_path)
    new = with_settings(plan, "selspot", {"leds": 6, "agc": "off"})
    assert settings_of(new, "selspot") == {**settings_of(plan, "selspot"), "leds": 6, "agc": "off"}
    assert settings_of(plan, "selspot")["leds"] == 8  # the plan given is not changed
    assert settings_of(with_rate(new, "timer", 50), "timer")["rate"] == 50.0
    bad = [
        ("nope", {"leds": 6}, "no device 'nope'"),
        ("selspot", {}, "at least one"),
        ("selspot", [("leds", 6)], "at least one"),
        ("selspot", {"exposure": 5}, "no setting 'exposure' (it has rate, cameras, leds"),
        ("selspot", {"leds": True}, "a number or a word"),
        ("selspot", {"leds": [6]}, "a number or a word"),
        ("selspot", {"leds": "six"}, "leds"),
        ("selspot", {"agc": "loud"}, "agc"),
    ]
    for name, settings, needle in bad:
        with pytest.raises(InputError, match=None) as exc:
            with_settings(plan, name, settings)
        assert needle in str(exc.value), (settings, str(exc.value))
    for rate in (-1, 0, "x", True):
        with pytest.raises(InputError, match="positive number"):
            with_rate(plan, "selspot", rate)
