"""The host side of the QTM protocol against the golden vectors of docs/protocols/qualisys.md."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from spotlab.core.errors import ConfigurationError, ProtocolError
from spotlab.drivers.qualisys import (
    PacketSplitter,
    QualisysDecoder,
    QualisysDriver,
    bodies_6d_from,
    command_packet,
    markers_2d_from,
    markers_3d_from,
    markers_no_labels_from,
    parse_address,
    parse_data,
    parse_parameters,
)
from spotlab.drivers.qualisys.protocol import COMMAND, DATA, ERROR, EVENT, NO_MORE_DATA, XML
from spotlab.drivers.qualisys.udp import UdpReceiver
from spotlab.testing.golden import golden_vector

SPEC = Path(__file__).parents[3] / "docs" / "protocols" / "qualisys.md"


def golden(name: str) -> bytes:
    """The bytes of golden vector ``name`` (``G1``...) as the spec writes them."""
    return golden_vector(SPEC, name)


def test_commands_are_the_golden_bytes() -> None:
    assert command_packet("Version 1.25") == golden("G1")
    assert command_packet("GetParameters 3D") == golden("G4")
    assert command_packet("StreamFrames AllFrames 3D 6D") == golden("G11")


def test_udp_stream_command_is_the_golden_bytes() -> None:
    driver = QualisysDriver("127.0.0.1:1", udp_port=7777)
    driver._udp = UdpReceiver("127.0.0.1", 0, "127.0.0.1")
    driver._udp.port = 7777  # as if bound there
    try:
        assert command_packet(driver._stream_command()) == golden("G12")
    finally:
        driver._udp.close()


def test_splitter_cuts_every_golden_reply_from_any_split() -> None:
    names = ("G3", "G2", "G5", "G6", "G8", "G7", "G9", "G10")
    stream = b"".join(golden(n) for n in names)
    split = PacketSplitter()
    got = [p for i in range(len(stream)) for p in split.feed(stream[i : i + 1])]
    assert [p.kind for p in got] == [COMMAND, COMMAND, XML, DATA, EVENT, DATA, NO_MORE_DATA, ERROR]
    assert got[0].text == "QTM RT Interface connected" and got[1].text == "Version set to 1.25"
    assert got[7].text == "Version NOT supported" and got[4].body == b"\x03"
    assert split.pending == 0 and split.bad_bytes == 0
    labels = [e for e in re.findall(r"<Name>(\w+)</Name>", got[2].text)]
    assert labels == ["LASI", "RASI"]


def test_golden_data_packets() -> None:
    frame = parse_data(golden("G6")[8:])
    assert (frame.timestamp_us, frame.frame, list(frame.components)) == (1_230_000, 124, [1])
    xyz = markers_3d_from(frame.components[1])
    assert np.array_equal(xyz[0], [100.5, -20.25, 950.0]) and np.isnan(xyz[1]).all()
    six = parse_data(golden("G7")[8:])
    pos, rot = bodies_6d_from(six.components[5])
    assert (six.timestamp_us, six.frame) == (10_000, 2)
    assert np.array_equal(pos, [[10.0, 20.0, 30.0]]) and np.array_equal(rot, np.eye(3)[None])


def test_decoder_on_golden_stream_and_garbage() -> None:
    dec = QualisysDecoder(2)
    block = dec.feed(golden("G3") + golden("G8") + golden("G6") + b"\xff" * 5 + golden("G9"), 7)
    assert block.seq.tolist() == [124] and block.ticks.tolist() == [1_230_000]
    assert block.data.shape == (1, 2, 1, 3) and block.flags[0, :, 0].tolist() == [0x80, 0]
    assert dec.events == [(0, 3, "capture started")]
    assert dec.stats.resyncs == 1 and dec.stats.bytes_skipped == 5
    assert len(QualisysDecoder(3).feed(golden("G6"), 0)) == 0  # another label count


def test_frame_numbers_losses_and_restarts() -> None:
    from spotlab.simulators import qualisys_wire as qw  # tests may use both sides

    dec = QualisysDecoder(1)
    one = np.zeros((1, 3))
    frames = [5, 6, 9, 10, 2, 3]
    stream = b"".join(qw.data_packet(n * 10, n, [qw.component_3d(one)]) for n in frames)
    block = dec.feed(stream, 0)
    assert block.seq.tolist() == [5, 6, 9, 10, 11, 12]
    assert dec.stats.lost_frames == 2 and dec.stats.gaps == 2


def test_parameters_and_addresses() -> None:
    xml = (
        "<QTM_Parameters_Ver_1.25><General><Frequency>250</Frequency><Camera/><Camera/>"
        "</General><The_3D><Label><Name> A </Name></Label><Label><Name>B</Name></Label>"
        "</The_3D><The_6D><Body><Name>rb</Name></Body></The_6D></QTM_Parameters_Ver_1.25>"
    )
    p = parse_parameters(xml)
    assert (p.rate_hz, p.labels, p.bodies, p.cameras) == (250.0, ("A", "B"), ("rb",), 2)
    with pytest.raises(ProtocolError, match="no frequency"):
        parse_parameters(golden("G5")[8:-1].decode())
    with pytest.raises(ProtocolError, match="DOCTYPE"):
        parse_parameters('<!DOCTYPE x [<!ENTITY a "b">]><x/>')
    assert parse_address("10.0.0.2") == ("10.0.0.2", 22223)
    assert parse_address("localhost:4000") == ("localhost", 4000)
    for bad in ("", ":22", "host:0", "host:x"):
        with pytest.raises(ConfigurationError):
            parse_address(bad)


@pytest.mark.parametrize("reader", [markers_3d_from, markers_no_labels_from, bodies_6d_from,
                                    markers_2d_from])  # fmt: skip
def test_short_components_are_protocol_errors(reader: object) -> None:
    for comp in (b"", b"\x01", b"\x05\x00\x00\x00\x00\x00\x00\x00"):
        with pytest.raises(ProtocolError):
            reader(comp)  # type: ignore[operator]


def test_mutated_streams_never_raise() -> None:
    """Blind mutations of a QTM byte stream, in random reads: the decoder never raises and
    the codec functions raise ProtocolError only."""
    import random

    from spotlab.simulators import qualisys_wire as qw
    from spotlab.simulators.qualisys_scene import QualisysScene
    from spotlab.testing.fuzz import mutate

    scene = QualisysScene(markers=40, cameras=2)
    parts = [qw.text_packet(qw.COMMAND, "QTM RT Interface connected")]
    for n in range(1, 8):
        f = scene.frame(n)
        comps = [
            qw.component_3d(f.markers),
            qw.component_6d(f.body_positions, f.body_rotations),
            qw.component_3d_no_labels(f.markers),
            qw.component_2d(scene.view_2d(f.markers)),
        ]
        parts += [qw.data_packet(scene.timestamp_us(n), n, comps), qw.event_packet(3)]
    clean = b"".join(parts)
    rng = random.Random(5)
    for _ in range(400):
        data = mutate(rng, clean, clean)
        dec = QualisysDecoder(40)
        pos = 0
        while pos < len(data):
            step = rng.choice((1, 7, 64, 512, 4096))
            dec.feed(data[pos : pos + step], pos)
            pos += step
        for p in PacketSplitter().feed(data):
            if p.kind != DATA:
                continue
            try:
                frame = parse_data(p.body)
                for kind, comp in frame.components.items():
                    reader = {1: markers_3d_from, 5: bodies_6d_from, 7: markers_2d_from}
                    reader.get(kind, markers_no_labels_from)(comp)
            except ProtocolError:
                pass
