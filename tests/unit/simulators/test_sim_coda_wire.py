"""Device side of the CSX bytes against the golden vectors of docs/protocols/coda.md §6."""

from __future__ import annotations

import math

import numpy as np
import pytest

from spotlab.simulators import coda_scene as scene
from spotlab.simulators import coda_wire as cw
from spotlab.simulators import wire
from spotlab.simulators.coda import CodaDevice

GOLDEN_FRAME = bytes.fromhex(
    "A5 5A 02 10 05 00 AC 00 FC 8D"
    "2C 01 00 00 40 42 0F 00 20 00 02 00"
    "03 06 02 0C"
    "01 0F 0F 27 00 00 D9 93 04 00 24 4E 00 00"
    "EC 30 62 13 36 25 27 08 3B 03 33 06"
    "1A 0F 55 9E FF FF 8E D0 03 00 F3 D8 FF FF"
    "2C 28 28 05 AC 1B B2 06 DC 00 9C 04" + "00" * 104 + "C7 4D"
)


def _record(code: str, p: tuple[float, float, float]) -> cw.MarkerRecord:
    """The spec's record of a marker at ``p`` (mm), from the spec's formulas."""
    angles = scene.mirror_angles(np.asarray([p]), 1000.0)[0]
    counts = np.asarray([[cw.angle_count(float(a)) for a in angles]], dtype=np.int64)
    sweep_us = 0.8 * 1e6 / 300
    dt = tuple(math.floor(sweep_us * int(c) / cw.COUNTS) for c in counts[0])
    xyz, valid = scene.device_xyz(counts, 1000.0)
    assert valid.all()
    cmm = tuple(int(v) for v in np.rint(xyz[0] * 100))
    return cw.MarkerRecord(cw.colour_id(code), 0x0F, cmm, tuple(counts[0].tolist()), dt)  # type: ignore[arg-type]


def test_golden_frame_from_the_spec_formulas() -> None:
    recs = [_record("RO", (100.0, 3000.0, 200.0)), _record("GB", (-250.0, 2500.0, -100.0))]
    assert recs[0].counts == (12524, 4962, 9526) and recs[0].dt_us == (2087, 827, 1587)
    assert recs[1].xyz_cmm == (-25003, 249998, -9997)
    payload = cw.csx_payload(300, 1_000_000, 0x0020, 3, 2, cw.marker_limit(300_000), recs)
    assert cw.csx_frame(5, payload) == GOLDEN_FRAME
    assert cw.csx_frame_length(2, 3) == len(GOLDEN_FRAME) == 184


@pytest.mark.parametrize(
    ("text", "golden"),
    [
        ("OKAY", b"OKAY26CF\r"),
        ("ERROR81", b"ERROR81DF72\r"),
        ("ERROR82", b"ERROR82EF11\r"),
        ("CSX 1.0 SIM00031 1000000 16000 40000", b"CSX 1.0 SIM00031 1000000 16000 40000F08F\r"),
        ("CONF RATE=300000 OUT=BOTH MARK=RO,GB", b"CONF RATE=300000 OUT=BOTH MARK=RO,GBF62E\r"),
    ],
)
def test_replies_match_the_golden_vectors(text: str, golden: bytes) -> None:
    assert wire.reply(text) == golden


def test_version_reply_is_the_golden_one() -> None:
    assert CodaDevice(now_ns=0).version_text() == "CSX 1.0 SIM00031 1000000 16000 40000"


def test_colour_table_and_limits() -> None:
    assert [cw.colour_id(c) for c in ("RO", "RW", "OR", "GB", "WV")] == [1, 7, 8, 26, 56]
    assert [cw.id_colour(i) for i in (1, 8, 26, 56)] == ["RO", "OR", "GB", "WV"]
    assert sorted(cw.colour_id(a + b) for a in cw.COLOURS for b in cw.COLOURS if a != b) == list(
        range(1, 57)
    )
    with pytest.raises(ValueError):
        cw.colour_id("RR")
    assert [cw.marker_limit(r) for r in (50_000, 100_000, 200_000, 300_000, 800_000)] == [
        56, 56, 28, 12, 6,
    ]  # fmt: skip
    assert cw.angle_count(math.radians(20.0)) == cw.NOT_SEEN
    assert cw.angle_count(math.radians(-20.0)) == 0
