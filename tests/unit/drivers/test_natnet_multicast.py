"""``--device natnet=HOST[,multicast=GROUP|off]``: frames sent to a multicast group.

The simulated Motive sends to 239.255.42.99 on the loopback interface and says so in
its server info; the driver joins the group (as announced, or as asked) and records
every frame, equal to the truth. Hosts that do not route multicast on loopback skip.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from spotlab.acquisition.replay import replay
from spotlab.console.cli import main
from spotlab.core.errors import ConfigurationError, DeviceNotFound
from spotlab.drivers.natnet import NatNetDriver
from spotlab.processing.decoding import decoder_for
from spotlab.simulators.natnet import MULTICAST_GROUP, NatNetServer
from spotlab.simulators.natnet_scene import NatNetScene


@pytest.fixture
def served(tmp_path: Path) -> Iterator[tuple[NatNetServer, Path]]:
    scene = NatNetScene(markers=10, cameras=2, rate_hz=100.0, seed=3)
    truth = tmp_path / "truth.npz"
    try:
        srv = NatNetServer(scene, truth=truth, multicast=True).start()
    except OSError as exc:
        pytest.skip(f"no free command/data port pair on loopback: {exc}")
    try:
        with NatNetDriver(srv.address) as probe:
            if probe.recv(1.0) is None:
                pytest.skip("this host does not deliver multicast on loopback")
    except DeviceNotFound as exc:
        srv.stop()
        pytest.skip(f"this host does not route multicast on loopback: {exc}")
    try:
        yield srv, truth
    finally:
        srv.stop()


@pytest.mark.parametrize("option", ["", f",multicast={MULTICAST_GROUP}"])
def test_record_joins_the_group_and_keeps_every_frame(
    served: tuple[NatNetServer, Path],
    option: str,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    srv, truth = served
    out = tmp_path / "rec.spj"
    code = main(["record", "--device", f"natnet={srv.address}{option}", "--seconds", "1.5",
                 "--out", str(out)])  # fmt: skip
    assert code == 0, capsys.readouterr().err
    blocks = [b for _, b in replay(out, decoder_for)]
    seq = np.concatenate([b.seq for b in blocks])
    data = np.concatenate([b.data for b in blocks])
    assert len(seq) >= 120 and np.all(np.diff(seq) == 1)
    srv.stop()
    t = np.load(truth)
    row = {int(k): i for i, k in enumerate(t["frame"])}
    want = t["markers_mm"][[row[int(k)] for k in seq]]
    want = (want / 1000.0).astype(np.float32).astype(np.float64) * 1000.0
    np.testing.assert_array_equal(data[:, :, 0, :], want)


def test_the_driver_says_which_group_it_joined(served: tuple[NatNetServer, Path]) -> None:
    srv, _ = served
    with NatNetDriver(srv.address) as drv:
        assert drv.recv(1.0) is not None
        meta = drv.metadata()
        assert drv.group == (MULTICAST_GROUP, srv.data_port)
    assert meta["multicast"] == f"{MULTICAST_GROUP}:{srv.data_port}"


def test_multicast_off_receives_no_frames_from_a_multicast_server(
    served: tuple[NatNetServer, Path],
) -> None:
    srv, _ = served
    drv = NatNetDriver(srv.address, multicast="off")
    with pytest.raises(DeviceNotFound, match="sends no frames"):
        drv.start()
    drv.close()


@pytest.mark.parametrize("bad", ["10.0.0.1", "239.1", "on"])
def test_multicast_takes_a_group_address(bad: str) -> None:
    with pytest.raises(ConfigurationError, match="multicast takes an IPv4 group"):
        NatNetDriver("127.0.0.1", multicast=bad)
