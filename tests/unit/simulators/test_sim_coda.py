"""The CSX scanner model: crossings, noise, occlusion and the flagged faults (coda.md §1, §4)."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest

from spotlab.simulators import coda_scene as scene
from spotlab.simulators import coda_wire as cw
from spotlab.simulators.clock import DeviceClock
from spotlab.simulators.coda import CodaConfig, CodaDevice, CodaFaults, CodaStream

BASE = 1000.0


def _scans(
    table: list[int], frames: int, rates: CodaFaults, rate_mhz: int = 300_000, markers: int = 16
) -> list[tuple[float, list[tuple[int, int, tuple[int, ...], tuple[int, ...], tuple[int, ...]]]]]:
    """(scan start s, records (id, flags, xyz, counts, dt)) of ``frames`` scans in BOTH mode."""
    device = CodaDevice(
        DeviceClock(epoch_ns=0), scene_markers=markers, fault_rates=rates, seed=7, now_ns=0
    )
    stream = CodaStream(device, CodaConfig(rate_mhz, 3, table), 10**8, 0)
    out = []
    for _ in range(frames):
        osc0 = stream._osc0
        payload = stream.take().payload
        n = struct.unpack_from("<H", payload, 10)[0]
        recs = []
        for i in range(n):
            r = struct.unpack_from("<BBiiiHHHHHH", payload, 16 + 26 * i)
            recs.append((r[0], r[1], r[2:5], r[5:8], r[8:11]))
        out.append((float(device.clock.world_ns(osc0)) / 1e9, recs))
    return out


def test_each_mirror_crosses_at_its_own_instant() -> None:
    quiet = CodaFaults(colour=0.0, ghost=0.0, occlusion=0.0)
    for _, recs in _scans([1, 2, 3, 4], 20, quiet):
        assert len(recs) == 4
        for _, flags, _, counts, dt in recs:
            assert flags == 0x0F
            assert len(set(dt)) == 3  # three different instants
            sweep_us = 0.8 * 1e6 / 300
            assert dt == tuple(int(np.floor(sweep_us * c / cw.COUNTS)) for c in counts)


def test_unflagged_records_are_the_marker_their_id_names() -> None:
    faulty = CodaFaults(colour=0.2, ghost=0.2, occlusion=0.0)
    flagged = {cw.F_COLOUR_AMBIGUOUS: 0, cw.F_GHOST: 0}
    for t0, recs in _scans(list(range(1, 9)), 60, faulty):
        truth = scene.marker_positions(np.arange(1, 9), np.asarray(t0))
        for marker, flags, xyz, _, _ in recs:
            for bit in flagged:
                flagged[bit] += bool(flags & bit)
            if flags & 0x70:
                continue
            # The device's 3-D is within a few mm of the marker its id names.
            assert np.linalg.norm(np.asarray(xyz) / 100 - truth[marker - 1]) < 20
    assert flagged[cw.F_COLOUR_AMBIGUOUS] > 20 and flagged[cw.F_GHOST] > 20


def test_ghosts_come_from_the_back_wall() -> None:
    only_ghosts = CodaFaults(colour=0.0, ghost=1.0, occlusion=0.0)
    _, recs = _scans([1, 2], 1, only_ghosts)[0]
    ghosts = [r for r in recs if r[1] & cw.F_GHOST]
    assert len(ghosts) == 2 and {r[0] for r in ghosts} == {1, 2}
    for _, _, xyz, _, _ in ghosts:
        assert xyz[1] / 100 == pytest.approx(2 * scene.GHOST_WALL_Y_MM - 3000, abs=400)


def test_markers_beyond_the_rate_limit_alias_flagged_under_the_lower_entry() -> None:
    quiet = CodaFaults(colour=0.0, ghost=0.0, occlusion=0.0)
    table = list(range(1, 15))  # 14 markers at 300 Hz: the limit is 12
    for _, recs in _scans(table, 5, quiet):
        aliased = [r for r in recs if r[1] & cw.F_ALIASED]
        assert sorted(r[0] for r in aliased) == [1, 1, 2, 2]
        assert all(r[0] not in (13, 14) for r in recs)


def test_occlusion_hides_a_mirror_and_invalidates_the_3d() -> None:
    occluding = CodaFaults(colour=0.0, ghost=0.0, occlusion=0.05)
    partial = 0
    for _, recs in _scans(list(range(1, 9)), 100, occluding):
        for _, flags, xyz, counts, dt in recs:
            if (flags & 0x0E) != 0x0E:
                partial += 1
                assert not flags & cw.F_3D_VALID and xyz == (0, 0, 0)
                assert cw.NOT_SEEN in counts and cw.NOT_SEEN in dt
    assert partial > 50


def test_angle_noise_grows_with_distance() -> None:
    rng = np.random.default_rng(0)
    angles = np.zeros((20_000, 3))
    near = scene.measure(angles, np.full(20_000, 1000.0), 0.0, rng)
    far = scene.measure(angles, np.full(20_000, 6000.0), 0.0, rng)
    assert far.std() / near.std() == pytest.approx(3.0, rel=0.15)
    sunlit = scene.measure(angles, np.full(20_000, 1000.0), 1.0, rng)
    assert sunlit.std() > 3 * near.std()


def test_commands_and_start_checks() -> None:
    from spotlab.simulators.commands import Command, CommandError

    device = CodaDevice(now_ns=0)
    with pytest.raises(CommandError) as err:
        device._check_start()
    assert err.value.code == 0x82
    with pytest.raises(CommandError) as err:
        device._csx_mark(Command("MARK", ("RO", "XX"), True), 0)
    assert err.value.code == 0x81
    with pytest.raises(CommandError) as err:
        device._csx_mark(Command("MARK", ("RO", "RO"), True), 0)
    assert err.value.code == 0x81
    with pytest.raises(CommandError) as err:
        device._csx_out(Command("OUT", ("2D",), True), 0)
    assert err.value.code == 0x23
    assert device._csx_mark(Command("MARK", ("RO", "GB"), True), 0) == "OKAY"
    assert device._csx_conf(Command("CONF", (), True), 0) == "CONF RATE=300000 OUT=BOTH MARK=RO,GB"
    with pytest.raises(CommandError) as err:
        device._check_start()  # 9600 baud after reset
    assert err.value.code == 0x80


def test_the_scanners_own_faults_are_in_its_fault_log(tmp_path: Path) -> None:
    """Each misread and ghost record is one log entry naming the marker and the ID sent;
    an aliased marker one entry per START counting its scans; the truth as npz."""
    rates = CodaFaults(colour=0.05, ghost=0.05, occlusion=0.0)
    truth = tmp_path / "truth.npz"
    device = CodaDevice(
        DeviceClock(epoch_ns=0), scene_markers=16, fault_rates=rates, seed=7, now_ns=0,
        truth=truth,
    )  # fmt: skip
    table = [*range(1, 13), 13]  # 300 Hz serves 12: entry 12 (ID 13) shares ID 1's slot
    stream = CodaStream(device, CodaConfig(300_000, 3, table), 10**8, 0)
    colour = ghost = 0
    for _ in range(200):
        taken = stream.take()
        device._truth.add(taken.truth)  # type: ignore[union-attr]
        taken.truth.sent = True
        payload = taken.payload
        for i in range(struct.unpack_from("<H", payload, 10)[0]):
            flags = payload[16 + 26 * i + 1]
            colour += bool(flags & cw.F_COLOUR_AMBIGUOUS)
            ghost += bool(flags & cw.F_GHOST)
    entries = device.fault_log.entries
    kinds = [e.kind for e in entries]
    assert kinds.count("colour") == colour > 0 and kinds.count("ghost") == ghost > 0
    assert all(e.source == "device" and e.frame_no for e in entries)
    misread = [e.detail for e in entries if e.kind == "colour"]
    assert all(d["marker"] != d["reported"] for d in misread)
    alias = {e.detail["marker"]: e.detail for e in entries if e.kind == "alias"}
    assert sorted(alias) == [1, 13] and all(d["reported"] == 1 for d in alias.values())
    assert all(d["scans"] == 200 for d in alias.values())
    device.close(catch_up=False)
    t = np.load(truth)
    assert t["markers_mm"].shape == (200, 17, 3) and t["time_s"].shape == (200,)
    assert np.all(t["sent"]) and list(t["frame_no"]) == list(range(200))
    assert np.isnan(t["markers_mm"][:, 0]).all() and np.isfinite(t["markers_mm"][:, 1:]).all()
