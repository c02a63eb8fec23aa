"""Data frames of a simulated stream: layout, timing, per-slot sampling, truth file, AGC, BGND."""

from __future__ import annotations

import csv
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from _simwire import MS, T0, Host, S, cmd, decode, spx

from spotlab.simulators import wire
from spotlab.simulators.motions import StaticMarkers, WandDance
from spotlab.simulators.psd import PsdModel
from spotlab.simulators.scene import Ambient, PsdCamera, Scene, ring_rig
from spotlab.simulators.selspot import SelspotDevice


def stream(h: Host, seconds: float, baud: int = 2_000_000) -> list[dict[str, object]]:
    h.buf.clear()
    h.send(cmd("START:"), baud=baud)
    h.wait(round(seconds * S))
    h.send(cmd("STOP:"), baud=baud)
    h.wait(20 * MS)
    got = decode(bytes(h.buf))
    assert got.crc_errors == 0
    return [
        spx(f["payload"]) | {"seq": f["seq"], "hflags": f["flags"]}
        for f in got.frames
        if f["type"] == 1
    ]  # type: ignore[arg-type]


def test_frames_layout_and_counters(host: Host) -> None:
    host.configure(4, 32, 200_000)
    frames = stream(host, 1.0)
    assert 199 <= len(frames) <= 201
    assert [f["seq"] for f in frames] == list(range(len(frames)))
    assert [f["frame_no"] for f in frames] == list(range(len(frames)))
    f0 = frames[0]
    assert (f0["n_leds"], f0["n_cams"], f0["n_items"], f0["slot_us"]) == (32, 4, 128, 100)
    assert f0["hflags"] == 0x14  # version 1, simulated device
    ticks = np.array([f["tick"] for f in frames], dtype=np.int64)
    assert np.all(np.abs(np.diff(ticks) - 5000) <= 1)
    # The first slot starts when START's last byte arrived (11 bytes at 2 Mbaud after the write).
    start_us = (host.t - round(1.0 * S) - 20 * MS - T0) / 1000  # noqa: F841 - documented, not asserted


def test_records_match_truth_sampled_per_slot(
    make_device: Callable[..., SelspotDevice], tmp_path: Path
) -> None:
    # A fast wand, no mirror, no detector non-linearity: records must be the truth reprojected.
    rig = ring_rig(2, k1=0.0)
    scene = Scene(WandDance(seed=3), rig)
    truth = tmp_path / "truth.csv"
    psd = PsdModel(pincushion=0.0, electrode_noise=0.0)
    h = Host(make_device(scene=scene, truth=truth, psd=psd))
    h.configure(2, 2, 100_000, extra=("SLOT:1000",))
    frames = stream(h, 0.5)
    h.dev.close(h.t)
    rows = list(csv.DictReader(truth.read_text().splitlines()))
    assert len(rows) == len(frames)
    worst, compared = 0.0, 0
    for f, row in zip(frames, rows, strict=True):
        assert int(row["seq"]) == f["seq"] and int(row["frame_no"]) == f["frame_no"]
        assert int(row["device_tick"]) == f["tick"] and row["sent"] == "1"
        for k in range(2):
            X = np.array([float(row[f"led{k}_{a}_mm"]) for a in "xyz"])
            # The truth is the motion at the LED's own slot time (k + 1/2) * 1 ms after the tick.
            t_slot = float(row["true_time_s"]) - T0 / 1e9 + (k + 0.5) * 1e-3
            np.testing.assert_allclose(
                X, scene.motion.sample(np.array([t_slot]), np.array([k]))[0], atol=1e-3
            )
            for c, cam in enumerate(rig):
                xc = cam.R @ X + cam.t
                u, v = cam.focal * xc[0] / xc[2] + 2048, cam.focal * xc[1] / xc[2] + 2048
                flags = f["flags"][k, c]  # type: ignore[index]
                # Saturated readings are pulled towards the centre (documented): the
                # operator's dance passes close to the cameras now and then.
                if flags & wire.FLAG_VALID and not flags & wire.FLAG_SATURATED:
                    worst = max(worst, abs(f["x"][k, c] - u), abs(f["y"][k, c] - v))  # type: ignore[index]
                    compared += 1
    assert compared > 0.5 * 4 * len(frames)
    assert worst <= 0.51


def test_truth_time_and_ticks_agree(
    make_device: Callable[..., SelspotDevice], tmp_path: Path
) -> None:
    truth = tmp_path / "t.csv"
    h = Host(make_device(truth=truth))
    h.configure(1, 4, 100_000)
    stream(h, 1.0)
    h.dev.flush(h.t)  # written while running, before close
    rows = list(csv.DictReader(truth.read_text().splitlines()))
    assert len(rows) >= 99
    for row in rows:
        world_us = (float(row["true_time_s"]) * 1e9 - T0) / 1000
        assert world_us == pytest.approx(int(row["device_us"]), abs=0.01)
    assert rows[0]["stream"] == "0"
    assert set(rows[0]) >= {
        "seq",
        "frame_no",
        "true_time_s",
        "device_tick",
        "sent",
        "led0_x_mm",
        "led31_z_mm",
    }
    assert rows[0]["led31_x_mm"] == "nan"  # not in the LED table


def test_truth_is_written_incrementally(
    make_device: Callable[..., SelspotDevice], tmp_path: Path
) -> None:
    truth = tmp_path / "t.csv"
    h = Host(make_device(truth=truth))
    h.configure(1, 4, 200_000)
    h.send(cmd("START:"), baud=2_000_000)
    h.wait(2 * S)
    lines = truth.read_text().splitlines()
    assert len(lines) > 300  # no close yet


def test_agc_steers_towards_the_target(make_device: Callable[..., SelspotDevice]) -> None:
    cam = PsdCamera.look_at((0, -2000, 1000), (0, 0, 1000), focal=2000)
    leds = StaticMarkers(
        [[0, 0, 1000], [200, 0, 1000], [0, 40_000, 1000]]
    )  # bright, bright, hopeless
    h = Host(make_device(scene=Scene(leds, [cam])))
    h.configure(1, 3, 100_000, extra=("AGC:1,160", "LEDT:00FF01100210"))
    frames = stream(h, 1.0)
    first, last = frames[0], frames[-1]
    assert first["intensity"][0, 0] == 255  # type: ignore[index]
    assert 120 <= last["intensity"][0, 0] <= 200  # type: ignore[index]
    assert 120 <= last["intensity"][1, 0] <= 200  # type: ignore[index]
    currents = h.ask("LEDQ:").split()[1]
    assert currents[2:4] != "FF" and currents[6:8] != "10"
    # LED 2 stays invalid: no valid intensity, so AGC leaves its current alone; no limit flag.
    assert currents[8:12] == "0210"
    assert not last["flags"][2, 0] & wire.FLAG_AGC_LIMIT  # type: ignore[index]


def test_agc_at_limit_is_flagged(make_device: Callable[..., SelspotDevice]) -> None:
    cam = PsdCamera.look_at((0, -2000, 1000), (0, 0, 1000), focal=2000)
    leds = StaticMarkers([[0, 8000, 1000]])  # seen, but too dim for the target even at 63.75 mA
    h = Host(make_device(scene=Scene(leds, [cam])))
    h.configure(1, 1, 100_000, extra=("AGC:1,250", "LEDT:00F0"))
    frames = stream(h, 0.5)
    assert frames[0]["flags"][0, 0] == wire.FLAG_VALID  # type: ignore[index]
    assert frames[-1]["flags"][0, 0] == wire.FLAG_VALID | wire.FLAG_AGC_LIMIT  # type: ignore[index]
    assert h.ask("LEDQ:") == "LEDQ 00FF"


def test_agc_off_keeps_currents(host: Host) -> None:
    host.configure(4, 8, 100_000)
    stream(host, 0.3)
    assert host.ask("LEDQ:") == "LEDQ " + "".join(f"{i:02X}80" for i in range(8))


@pytest.mark.parametrize("bgnd", [0, 1, 2])
def test_background_differencing_modes(
    make_device: Callable[..., SelspotDevice], bgnd: int
) -> None:
    cam = PsdCamera.look_at((0, -3000, 1000), (0, 0, 1000), focal=2000)
    amb = Ambient(level=50.0, flicker=0.5, centroid=(3500.0, 2048.0))
    scene = Scene(StaticMarkers([[0, 0, 1000]] * 1 + [[0, 10, 1000]] * 7), [cam], ambient=amb)
    h = Host(make_device(scene=scene, psd=PsdModel(electrode_noise=0.0)))
    h.configure(1, 8, 50_000, extra=(f"BGND:{bgnd}",))
    frames = stream(h, 0.5)
    err = np.concatenate([np.abs(f["x"][:, 0] - 2048) for f in frames])  # type: ignore[index]
    status = frames[-1]["status"]
    assert status & wire.STATUS_AMBIENT_HIGH if bgnd else True  # type: ignore[operator]
    mean = float(err.mean())
    if bgnd == 0:
        assert mean > 300  # ambient light pulls every reading towards its centroid
    elif bgnd == 1:
        assert mean < 5  # dark sample in the same slot: flicker barely changes in 20 us
    else:
        assert 5 < mean < 200  # one dark slot per frame: flicker changes across the frame


def test_ambient_high_status_bit(make_device: Callable[..., SelspotDevice]) -> None:
    scene = Scene(WandDance(), ring_rig(2), ambient=Ambient(level=100.0))
    h = Host(make_device(scene=scene))
    h.configure(2, 2, 100_000)
    frames = stream(h, 0.1)
    assert all(f["status"] & wire.STATUS_AMBIENT_HIGH for f in frames)  # type: ignore[operator]
    assert h.ask("STAT:") == "STAT 0022"


def test_led_ids_not_in_the_scene_are_never_seen(make_device: Callable[..., SelspotDevice]) -> None:
    h = Host(make_device(leds=4))
    h.configure(4, 4, 100_000, extra=("LEDT:00807F80",))
    frames = stream(h, 0.2)
    assert all(np.all(f["x"][1] == 0xFFF) for f in frames)  # type: ignore[index]
    assert any(np.any(f["flags"][0] & wire.FLAG_VALID) for f in frames)  # type: ignore[index]


def test_restart_begins_a_new_stream(host: Host) -> None:
    host.configure(1, 4, 100_000)
    first = stream(host, 0.2)
    second = stream(host, 0.2)
    assert second[0]["seq"] == 0 and second[0]["frame_no"] == 0
    assert second[0]["tick"] > first[-1]["tick"]  # type: ignore[operator]
    assert not second[0]["status"] & wire.STATUS_CONFIG_CHANGED  # type: ignore[operator]
