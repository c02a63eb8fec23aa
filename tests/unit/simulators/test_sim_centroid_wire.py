"""The device side of the CEN bytes against the golden vectors of docs/protocols/centroid.md §5."""

from __future__ import annotations

from pathlib import Path

import pytest

from spotlab.simulators import centroid_wire as cw
from spotlab.simulators import wire
from spotlab.testing.golden import golden_vector

SPEC = Path(__file__).parents[3] / "docs" / "protocols" / "centroid.md"
GOLDEN_FRAME = golden_vector(SPEC, "Data frame")
GOLDEN_OVERFLOW = golden_vector(SPEC, "Overflowing camera")


def golden_records() -> list[cw.CameraRecord]:
    blobs = cw.quantise_blobs(
        [[640.5, 512.25], [12.03125, 1000.0], [100.0, 200.0]],
        [38, 9, 70],
        [201, 255, 180],
        [0, cw.BLOB_SATURATED | cw.BLOB_EDGE, cw.BLOB_MERGED],
    )
    return [
        cw.CameraRecord(0, 0, 3, 1234, 12_345_678_901, blobs),
        cw.CameraRecord(2, cw.CAM_OFFLINE, 0, 1200, 0, blobs[:0]),
    ]


def test_data_frame_matches_the_golden_vector() -> None:
    payload = cw.cen_payload(1234, 0x71FB04CB, 0x0020, 0x0005, 4, 500, 128, golden_records())
    frame = cw.cen_frame(7, payload, wire.header_flags())
    assert frame == GOLDEN_FRAME
    assert len(frame) == cw.cen_frame_length(2, 3) == 96


def test_overflow_frame_matches_the_golden_vector() -> None:
    blobs = cw.quantise_blobs([[1.0, 2.0]], [5], [90], [0])
    record = cw.CameraRecord(0, cw.CAM_OVERFLOW, 7, 0, 1000, blobs)
    assert cw.cen_frame(0, cw.cen_payload(0, 0, 0, 1, 1, 500, 128, [record])) == GOLDEN_OVERFLOW


@pytest.mark.parametrize(
    ("text", "golden"),
    [
        ("CAMS:255", b"CAMS:255C6B4\r"),
        ("EXPO:500", b"EXPO:500ABBE\r"),
        ("THRS:128", b"THRS:128D939\r"),
        ("BLOB:256", b"BLOB:2567E45\r"),
        ("RATE:300000", b"RATE:300000CB66\r"),
        ("COMM:11", b"COMM:112E09\r"),
        ("COMM:12", b"COMM:121E6A\r"),
    ],
)
def test_commands_match_the_golden_vectors(text: str, golden: bytes) -> None:
    assert wire.command(text) == golden


def test_version_reply_matches_the_golden_vector() -> None:
    assert wire.reply("CEN 1.0 SIM00091 8 1024 1000000") == b"CEN 1.0 SIM00091 8 1024 1000000B960\r"


def test_more_blobs_than_the_cap_are_refused() -> None:
    record = golden_records()[0]
    with pytest.raises(ValueError, match="cap 2"):
        cw.cen_payload(0, 0, 0, 1, 2, 500, 128, [record])


def test_coordinates_quantise_to_a_32nd_of_a_pixel() -> None:
    blobs = cw.quantise_blobs([[3.0 + 1 / 64 + 1e-6, 5.5]], [4], [100], [0])
    assert int(blobs["x"][0]) == 97 and int(blobs["y"][0]) == 176
