"""The figures a long run is judged by (memory and latency flat), one stream of a
recording as its own journal, and the lab-preparation steps a scenario names."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from spotlab.hil.memory import MemorySampler, memory_figures, rss_mb, sample_interval
from spotlab.hil.scenario import ScenarioError, load_scenario
from spotlab.hil.scoring import _latency_drift, _latency_windows
from spotlab.hil.streams import one_stream
from spotlab.io.journal import JournalReader, JournalWriter, RecordType


def test_memory_figures_start_after_the_warm_up_and_end_at_the_last_sample() -> None:
    samples = [(t, {"record": 100.0 + t, "sim": 50.0}) for t in (0.0, 1.0, 5.0, 50.0, 100.0)]
    found = memory_figures(samples, 100.0)  # warm-up max(2 s, 5 %) = 5 s
    assert found["record_rss_start_mb"] == 105.0 and found["record_rss_end_mb"] == 200.0
    assert found["record_rss_growth_mb"] == 95.0 and found["record_rss_peak_mb"] == 200.0
    assert memory_figures([(0.5, {"record": 1.0})], 100.0)["record_rss_growth_mb"] is None
    assert sample_interval(3600.0) == 10.0 and sample_interval(8.0) == 0.5


def test_the_sampler_reads_this_process(tmp_path: Path) -> None:
    assert (rss_mb(os.getpid()) or 0.0) > 1.0
    sampler = MemorySampler({"me": os.getpid()}, 0.01).start()
    sampler.stop()
    assert sampler.samples and sampler.samples[0][1]["me"] is not None
    text = sampler.write_csv(tmp_path / "m.csv").read_text().splitlines()
    assert text[0] == "t_s,me_rss_mb" and len(text) == len(sampler.samples) + 1


def test_latency_at_the_start_and_the_end_of_a_stream() -> None:
    t = np.arange(0.0, 100.0, 0.01)
    age = np.where(t < 50.0, 5.0, 8.0)  # grows by 3 ms half way
    found = _latency_drift(t, age)
    assert found["latency_p50_start_ms"] == 5.0 and found["latency_p50_end_ms"] == 8.0
    assert found["latency_p50_growth_ms"] == 3.0
    rows = _latency_windows("s", t, age)
    assert len(rows) == 60 and rows[0][3] == "5.000" and rows[-1][3] == "8.000"


def test_one_stream_of_a_recording_is_copied_alone(tmp_path: Path) -> None:
    path = tmp_path / "two.spj"
    with JournalWriter(path, {"subject": "x"}) as j:
        a = j.add_stream("a", {"family": "selspot"})
        b = j.add_stream("b", {"family": "timer"})
        j.rx(a, b"aaa", 10)
        j.rx(b, b"bbb", 11)
        j.event(a, "disconnected", {"why": "test"}, 12)
        j.rx(a, b"AAA", 13)
    out = one_stream(path, "a", tmp_path / "a.spj")
    reader = JournalReader(out)
    records = list(reader)
    assert reader.streams == {"a": {"family": "selspot"}}
    assert [r.payload for r in records if r.type == RecordType.RX] == [b"aaa", b"AAA"]
    assert [r.t_ns for r in records if r.type == RecordType.RX] == [10, 13]
    assert any(r.type == RecordType.EVENT for r in records)
    assert reader.scan().session["subject"] == "x" and reader.complete


BASE = """\
duration = 3.0

[[device]]
family = "selspot"
name = "s"
[[device]]
family = "timer"
name = "t"

[processing]
steps = {steps}
{criteria}"""


@pytest.mark.parametrize(
    ("steps", "criteria", "message"),
    [
        ('["model"]', "", "'model' takes a single centroid device or more: none here"),
        ('["reconstruction"]', "[criteria.t]\nerror_3d_rms_mm = { max = 1 }",
         "criteria.t.error_3d_rms_mm: this figure needs a selspot device and the "
         "'reconstruction' step"),
        ('["reconstruction"]', "[criteria.s]\nerror_3d_excess = { max = 1 }",
         "criteria.s.error_3d_excess: this figure needs a selspot device and the "
         "'calibration' step"),
    ],
)  # fmt: skip
def test_preparation_steps_and_their_figures_are_checked(
    tmp_path: Path, steps: str, criteria: str, message: str
) -> None:
    path = tmp_path / "s.toml"
    path.write_text(BASE.format(steps=steps, criteria=criteria))
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    assert message in str(info.value), info.value


def test_a_scenario_may_calibrate_and_reconstruct_several_systems(tmp_path: Path) -> None:
    path = tmp_path / "s.toml"
    crit = "[criteria.s]\nerror_3d_excess = { max = 1.5 }\ncalibration_rms = { max = 3 }"
    path.write_text(BASE.format(steps='["calibration", "reconstruction"]', criteria=crit))
    s = load_scenario(path)
    assert s.steps == ("calibration", "reconstruction") and len(s.criteria) == 2
