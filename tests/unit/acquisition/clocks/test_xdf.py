"""Our clock model on real LSL recordings, against pyxdf's own synchronisation."""

from __future__ import annotations

import numpy as np
import pytest

from spotlab.acquisition.clocks import fit_xdf_offsets, load_xdf_clocks
from spotlab.core.errors import ClockError, RecordingError

pyxdf = pytest.importorskip("pyxdf")

#: Our Huber IRLS (1.5 robust SDs) and pyxdf's Huber ADMM (residuals scaled by 1e-4 s)
#: weight the scattered LSL offsets differently; the slopes differ by < 0.2 ppm, which
#: over the 400 s of clock_resets.xdf is up to 65 µs at the ends of a segment.
TOLERANCE_S = 100e-6


@pytest.mark.parametrize("name", ["minimal.xdf", "clock_resets.xdf", "empty_streams.xdf"])
def test_reproduces_pyxdf_synchronisation(shared_data, name):
    path = shared_data / "xdf_example_files" / name
    ours = load_xdf_clocks(path)
    theirs, _ = pyxdf.load_xdf(str(path), synchronize_clocks=True, dejitter_timestamps=False)
    assert len(ours) == len(theirs)
    for mine, ref in zip(ours, theirs, strict=True):
        stamps = np.asarray(ref["time_stamps"], dtype=np.float64)
        assert mine.synchronized.shape == stamps.shape
        if stamps.size:
            assert np.max(np.abs(mine.synchronized - stamps)) < TOLERANCE_S


def test_minimal_file_offset_is_exact(shared_data):
    # pyxdf's test_data.py: stream 0 time stamps 5.1 ... 5.9 minus the 0.1 s offset
    (first, _) = load_xdf_clocks(shared_data / "xdf_example_files" / "minimal.xdf")
    np.testing.assert_allclose(first.synchronized, np.arange(9) * 0.1 + 5.0, atol=1e-9)


def test_clock_reset_is_an_event(shared_data):
    streams = load_xdf_clocks(shared_data / "xdf_example_files" / "clock_resets.xdf")
    for stream in streams:
        assert stream.model is not None
        assert [e.kind for e in stream.model.events] == ["reset"]
        # the stream's clock jumped back by ~653 461 s relative to the recorder
        assert stream.model.events[0].size_s == pytest.approx(-653461.45, abs=0.01)
        assert stream.model.epochs == 2
        # a few ppm between two LSL clocks of one host
        assert np.all(np.abs(stream.model.segment_drift_ppm) < 10)
        # LSL offsets scatter by about 0.1 ms (measured: 124 µs and 92 µs robust SD)
        assert stream.model.jitter_s < 200e-6


def test_bad_offsets_and_files(tmp_path):
    with pytest.raises(ClockError, match="NaN"):
        fit_xdf_offsets([1.0, 2.0, np.nan], [0.0, 0.0, 0.0])
    with pytest.raises(ClockError, match="no clock offsets"):
        fit_xdf_offsets([], [])
    bad = tmp_path / "bad.xdf"
    bad.write_bytes(b"not an xdf file")
    with pytest.raises(RecordingError, match="cannot read"):
        load_xdf_clocks(bad)
