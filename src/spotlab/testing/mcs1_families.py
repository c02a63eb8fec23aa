"""The MCS-1 families as the shared conformance suite sees them (:class:`Mcs1Family`).

One description per family: its simulator (the options CI runs it with), its
driver, what its ``VER:0`` reply, its parameter checks and its frames look
like, and the family's own checks of a stream (timer pulses and timecode, blob
tables, the SPX slot period). ``tests/conformance/test_<family>.py`` runs the
suite on each and adds the family's extra tests.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from spotlab.core.frames import FrameBlock
from spotlab.drivers.centroid import CentroidDriver, blobs_from_blocks
from spotlab.drivers.coda import CodaDriver
from spotlab.drivers.selspot import SelspotDriver
from spotlab.drivers.timer import TimerDriver, extract_edges
from spotlab.simulators import service
from spotlab.simulators.centroid_service import (
    CentroidSimOptions,
    centroid_url_for,
    serve_centroid_pty,
)
from spotlab.simulators.coda_service import CodaSimOptions, coda_url_for, serve_coda_pty
from spotlab.testing.mcs1_conformance import Mcs1Family

_SELSPOT_SIM = service.SelspotSimOptions(cameras=4, leds=32, seed=3)
_TIMER_SIM = service.TimerSimOptions(seed=3)
_CENTROID_SIM = CentroidSimOptions(cameras=4, markers=20, seed=5)
_CODA_SIM = CodaSimOptions(markers=8, seed=3)


def _check_selspot_stream(driver: SelspotDriver, blocks: list[FrameBlock]) -> None:
    assert driver.spec.slot_period_s == pytest.approx(100e-6)


def _check_timer_stream(driver: TimerDriver, blocks: list[FrameBlock]) -> None:
    edges = extract_edges(blocks)
    assert np.all(np.diff(edges.frame_seqs) == 1)
    assert abs(np.median(np.diff(edges.frame_ticks)) - 100_000) < 100
    pulses = edges.select(0x80 | 2)  # POUT:2,5000: a pulse every 5 ms on output 2
    assert len(pulses) >= 100
    assert np.all(pulses.tick % 50_000 == 0)
    assert np.all(np.diff(pulses.tick) == 50_000)
    tc = np.concatenate([b.data[:, -1, 0, :] for b in blocks])
    assert np.all(tc[:, 2] == 25) and np.all(tc[:, 1] < 25)


def _check_centroid_stream(driver: CentroidDriver, blocks: list[FrameBlock]) -> None:
    blobs = blobs_from_blocks(blocks)
    assert np.all(np.diff(blobs.seq) == 1)
    assert abs(np.median(np.diff(blobs.ticks)) - 10_000) < 10
    # Each camera's own clock advances by one period per frame (within 200 ppm).
    step = np.diff(blobs.exposure_us, axis=0)
    assert np.nanmax(np.abs(step - 10_000)) < 2 + 10_000 * 2e-4
    assert (blobs.counts <= 128).all() and blobs.counts.sum() > 0


def _check_coda_stream(driver: CodaDriver, blocks: list[FrameBlock]) -> None:
    data = np.concatenate([b.data for b in blocks])
    flags = np.concatenate([b.flags for b in blocks])
    m = driver.config.n_markers
    assert data.shape[1] == 2 * m + 4
    # The table's rows hold only unflagged records of their own ID.
    used = flags[:, :m, 0] != 0
    assert (flags[:, :m, 0][used] & 0x70 == 0).all()
    ids = data[:, :m, 0, 0]
    assert (ids[used] == np.broadcast_to(np.asarray(driver.config.ids), ids.shape)[used]).all()
    # Markers are seen most of the time, some 3 m in front of the unit.
    assert used.mean() > 0.9
    depth = data[:, :m, 0, 2]
    assert 2000 < np.nanmedian(depth) < 4000
    # Each mirror crosses at its own instant within the sweep (0.8 of the 5 ms scan).
    dt = data[:, :m, 0, 7:10]
    assert np.nanmax(dt) < 4000 and (np.nanstd(dt, axis=2) > 0).any()
    assert driver.spec.metadata["geometry"]["base_mm"] == 1000.0


def _selspot_bandwidth() -> list[tuple[str, str]]:
    # 4 cameras x 32 LEDs at 200 Hz need 1.34 Mbit/s; 9600 baud cannot carry it.
    table = "".join(f"{i:02X}80" for i in range(32))
    return [("CAMS:4", "OKAY"), (f"LEDT:{table}", "OKAY"), ("RATE:200000", "OKAY"),
            ("START:", "ERROR80")]  # fmt: skip


SELSPOT = Mcs1Family(
    name="selspot",
    code="SPX",
    driver=SelspotDriver,
    serve_pty=lambda: service.serve_pty(_SELSPOT_SIM),
    sim_url=lambda: service.url_for(_SELSPOT_SIM),
    version_words=5,
    version_ranges={3: (1, 4), 4: (1, 128)},
    rejected=[("CAMS:5", "ERROR23"), ("SLOT:20", "ERROR23"), ("BGND:3", "ERROR23")],
    accepted=["CAMS:2", "LEDT:00800180", "SLOT:100", "RATE:100000", "BGND:1", "AGC:0,128"],
    bandwidth=_selspot_bandwidth(),
    stream={"cameras": 1, "leds": 8, "rate_hz": 100.0, "baud": 115_200},
    frames=60,
    period_ticks=10_000,  # µs
    period_tolerance=100,
    frame_shape=(8, 1, 3),
    refused_while_streaming="CAMS:2",
    check_stream=_check_selspot_stream,
)

TIMER = Mcs1Family(
    name="timer",
    code="TMR",
    driver=TimerDriver,
    serve_pty=lambda: service.serve_timer_pty(_TIMER_SIM),
    sim_url=lambda: service.timer_url_for(_TIMER_SIM),
    version_words=6,
    version_ranges={3: (1, math.inf), 5: (10_000_000, 10_000_000)},
    rejected=[
        ("EDGS:0", "ERROR23"),
        ("RATE:999", "ERROR23"),
        ("ARM:9,1", "ERROR23"),
        ("ARM:0,4", "ERROR23"),
        ("ARM:0", "ERROR07"),
        ("TCOD:1,25,1", "ERROR23"),  # drop-frame only at 30
    ],
    accepted=["RATE:250000", "EDGS:4", "ARM:0,3", "TCOD:1,30,1", "POUT:0,1000", "TCOD:0"],
    # 140-byte frames at 100 Hz need more than 9600 baud
    bandwidth=[("START:", "ERROR80")],
    stream={"rate_hz": 100.0, "slots": 4, "timecode": (25, False)},
    frames=60,
    period_ticks=100_000,  # 10 MHz ticks
    period_tolerance=100,
    frame_shape=(5, 1, 4),
    refused_while_streaming="EDGS:2",
    while_streaming=["POUT:2,5000"],
    check_stream=_check_timer_stream,
)

CENTROID = Mcs1Family(
    name="centroid",
    code="CEN",
    driver=CentroidDriver,
    serve_pty=lambda: serve_centroid_pty(_CENTROID_SIM),
    sim_url=lambda: centroid_url_for(_CENTROID_SIM),
    version_words=6,
    version_ranges={3: (1, 16), 4: (1, 1024), 5: (1_000_000, 1_000_000)},
    rejected=[
        ("RATE:999", "ERROR23"),
        ("CAMS:0", "ERROR23"),
        ("CAMS:65536", "ERROR23"),
        ("EXPO:19", "ERROR23"),
        ("THRS:255", "ERROR23"),
        ("BLOB:1025", "ERROR23"),
        ("BLOB:1,2", "ERROR07"),
    ],
    accepted=["RATE:300000", "CAMS:1", "EXPO:800", "THRS:100", "BLOB:64", "INIT:"],
    # 1 ms exposure in a 1 ms period is refused; then 1 kHz frames need more than 9600 baud
    bandwidth=[
        ("RATE:1000000", "OKAY"),
        ("EXPO:1000", "OKAY"),
        ("START:", "ERROR23"),
        ("EXPO:500", "OKAY"),
        ("START:", "ERROR80"),
    ],
    stream={"cameras": 2, "rate_hz": 100.0, "max_blobs": 128},
    frames=40,
    period_ticks=10_000,  # µs
    period_tolerance=10,
    frame_shape=(None, 2, 4),
    refused_while_streaming="BLOB:8",
    check_stream=_check_centroid_stream,
)

CODA = Mcs1Family(
    name="coda",
    code="CSX",
    driver=CodaDriver,
    serve_pty=lambda: serve_coda_pty(_CODA_SIM),
    sim_url=lambda: coda_url_for(_CODA_SIM),
    version_words=6,
    version_ranges={3: (100_000, 5_000_000), 4: (16_000, 16_000), 5: (40_000, 40_000)},
    rejected=[
        ("RATE:49999", "ERROR23"),
        ("RATE:800001", "ERROR23"),
        ("MARK:RO,XX", "ERROR81"),  # a code outside the colour table
        ("MARK:RO,RO", "ERROR81"),
        ("OUT:2D", "ERROR23"),
        ("OUT:3D,RAW", "ERROR07"),
    ],
    accepted=["RATE:100000", "OUT:3D", "MARK:RO,GB,WV", "OUT:BOTH", "INIT:"],
    # no marker table after reset; then 9600 baud cannot carry the frames
    bandwidth=[("START:", "ERROR82"), ("MARK:RO,GB", "OKAY"), ("START:", "ERROR80")],
    stream={"markers": 4, "rate_hz": 200.0, "mode": "BOTH"},
    frames=60,
    period_ticks=5_000,  # µs
    period_tolerance=10,
    frame_shape=(12, 1, 10),
    refused_while_streaming="MARK:RO",
    check_stream=_check_coda_stream,
)

#: Every MCS-1 family, by name.
FAMILIES: dict[str, Mcs1Family] = {f.name: f for f in (SELSPOT, TIMER, CENTROID, CODA)}

__all__ = ["CENTROID", "CODA", "FAMILIES", "SELSPOT", "TIMER"]
