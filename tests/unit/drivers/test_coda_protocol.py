"""Host side of the CSX bytes against the golden vectors of docs/protocols/coda.md §6."""

from __future__ import annotations

import math

import numpy as np
import pytest

from spotlab.core.errors import BandwidthError, ConfigurationError, ProtocolError
from spotlab.drivers.coda import CodaConfig, CodaDecoder, decoder_from_metadata
from spotlab.drivers.coda.config import marker_code, marker_id
from spotlab.drivers.coda.protocol import parse_version
from spotlab.drivers.mcs1.commands import encode_command
from spotlab.simulators import coda_wire as cw

GOLDEN_FRAME = bytes.fromhex(
    "A5 5A 02 10 05 00 AC 00 FC 8D"
    "2C 01 00 00 40 42 0F 00 20 00 02 00"
    "03 06 02 0C"
    "01 0F 0F 27 00 00 D9 93 04 00 24 4E 00 00"
    "EC 30 62 13 36 25 27 08 3B 03 33 06"
    "1A 0F 55 9E FF FF 8E D0 03 00 F3 D8 FF FF"
    "2C 28 28 05 AC 1B B2 06 DC 00 9C 04" + "00" * 104 + "C7 4D"
)
COUNT_RAD = math.radians(40.0) / 16000


def _rad(count: int) -> float:
    return (count - 8000) * COUNT_RAD


def test_golden_frame_decodes_to_the_documented_values() -> None:
    decoder = CodaDecoder((1, 26), "BOTH")
    block = decoder.feed(GOLDEN_FRAME, 1000)
    assert block.seq.tolist() == [5]
    assert block.ticks.tolist() == [1_000_000]
    assert block.status.tolist() == [0x20]
    assert block.data.shape == (1, 2 + 6, 1, 10)
    rows = block.data[0, :, 0]
    assert rows[0, :4].tolist() == [1, 99.99, 2999.93, 200.04]
    assert rows[0, 4:7] == pytest.approx([_rad(12524), _rad(4962), _rad(9526)])
    assert rows[0, 7:].tolist() == [2087, 827, 1587]
    assert rows[1, :4].tolist() == [26, -250.03, 2499.98, -99.97]
    assert rows[1, 7:].tolist() == [1714, 220, 1180]
    assert np.isnan(rows[2:]).all()
    assert block.flags[0, :2, 0].tolist() == [0x8F, 0x8F]
    assert decoder.stats.crc_errors == 0


def test_table_order_decides_the_rows_not_the_frame_order() -> None:
    block = CodaDecoder((26, 1), "BOTH").feed(GOLDEN_FRAME, 0)
    assert block.data[0, :2, 0, 0].tolist() == [26, 1]


def _frame(records: list[cw.MarkerRecord], n_markers: int, mode: int = 3) -> bytes:
    payload = cw.csx_payload(0, 0, 0, mode, n_markers, 12, records)
    return cw.csx_frame(0, payload)


def test_flagged_records_never_land_in_a_marker_row() -> None:
    recs = [
        cw.MarkerRecord(1, 0x0F, (100, 300000, 0), (9000, 7000, 8000), (1, 2, 3)),
        cw.MarkerRecord(2, 0x0F | cw.F_COLOUR_AMBIGUOUS, (1, 2, 3)),
        cw.MarkerRecord(3, 0x0F | cw.F_ALIASED, (4, 5, 6)),
        cw.MarkerRecord(1, 0x0F | cw.F_GHOST, (7, 8, 9)),
        cw.MarkerRecord(9, 0x0F, (7, 8, 9)),  # not in the table
    ]
    decoder = CodaDecoder((1, 2, 3), "BOTH")
    block = decoder.feed(_frame(recs, 3), 0)
    rows = block.data[0, :, 0]
    assert rows[0, :4].tolist() == [1, 1.0, 3000.0, 0.0]
    assert np.isnan(rows[1:3]).all()  # markers 2 and 3: only flagged records
    assert rows[3:7, 0].tolist() == [2, 3, 1, 9]
    assert np.isnan(rows[7:]).all()
    assert decoder.suspect_records == 4


def test_two_unflagged_records_of_one_id_are_both_unidentified() -> None:
    recs = [cw.MarkerRecord(1, 0x0F, (1, 1, 1)), cw.MarkerRecord(1, 0x0F, (2, 2, 2))]
    block = CodaDecoder((1,), "3D").feed(_frame(recs, 1, mode=1), 0)
    assert np.isnan(block.data[0, 0, 0]).all()
    assert block.data[0, 1:3, 0, 1].tolist() == [0.01, 0.02]


def test_modes_and_unseen_angles() -> None:
    rec = cw.MarkerRecord(1, 0x0A, (5, 5, 5), (cw.NOT_SEEN, 7000, 8000), (cw.NOT_SEEN, 5, 6))
    raw = CodaDecoder((1,), "RAW").feed(_frame([rec], 1, mode=2), 0).data[0, 0, 0]
    assert np.isnan(raw[1:4]).all() and np.isnan(raw[4]) and np.isnan(raw[7])
    assert raw[5] == pytest.approx(_rad(7000)) and raw[9] == 6
    both = CodaDecoder((1,), "BOTH").feed(_frame([rec], 1), 0).data[0, 0, 0]
    assert np.isnan(both[1:4]).all()  # not 3D valid


def test_frames_of_another_configuration_are_dropped() -> None:
    decoder = CodaDecoder((1, 26), "3D")
    assert decoder.feed(GOLDEN_FRAME, 0).data.shape[0] == 0


@pytest.mark.parametrize(
    ("verb", "args", "golden"),
    [
        ("MARK", "RO,GB", b"MARK:RO,GB30D4\r"),
        ("OUT", "BOTH", b"OUT:BOTH08B6\r"),
        ("OUT", "3D", b"OUT:3D724E\r"),
        ("RATE", "300000", b"RATE:300000CB66\r"),
    ],
)
def test_commands_encode_to_the_golden_vectors(verb: str, args: str, golden: bytes) -> None:
    assert encode_command(verb, args) == golden


def test_version_reply_carries_the_geometry() -> None:
    v = parse_version("CSX 1.0 SIM00031 1000000 16000 40000")
    assert (v.base_um, v.counts, v.fov_mdeg, v.serial_number) == (
        1_000_000,
        16000,
        40000,
        "SIM00031",
    )
    with pytest.raises(ProtocolError, match="CSX <firmware> <serial>"):
        parse_version("TMR 1.0 X 8 4 10000000")


def test_colour_codes() -> None:
    assert marker_id("RO") == 1 and marker_id("gb") == 26 and marker_id("WV") == 56
    assert [marker_id(marker_code(i)) for i in range(1, 57)] == list(range(1, 57))
    with pytest.raises(ConfigurationError, match="not in the colour table"):
        marker_id("RR")
    with pytest.raises(ConfigurationError, match="not in the colour table"):
        CodaConfig.create(markers="RO,XX")


def test_config_commands_bandwidth_and_round_trip() -> None:
    c = CodaConfig.create(rate_hz=300, markers=8)
    assert c.commands() == [("RATE", "300000"), ("OUT", "BOTH"),
                            ("MARK", "RO,RY,RG,RC,RB,RV,RW,OR")]  # fmt: skip
    assert c.frame_bytes == 340 and c.limit == 12
    assert CodaConfig.from_dict(c.to_dict()) == c
    assert decoder_from_metadata({"config": c.to_dict()}).markers == tuple(range(1, 9))
    with pytest.raises(BandwidthError, match="use baud=2000000"):
        CodaConfig.create(rate_hz=300, markers=8, baud=921_600)
    assert CodaConfig.create(rate_hz=300, markers=8, baud="auto").baud == 2_000_000
    with pytest.raises(ConfigurationError, match="50-800 Hz"):
        CodaConfig.create(rate_hz=1000)
    with pytest.raises(ConfigurationError, match="twice"):
        CodaConfig.create(markers="RO,ro")
