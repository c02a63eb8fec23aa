"""sim:// hands bytes to the host in 1 ms batches, as a USB-serial adapter does."""

from __future__ import annotations

import spotlab.simulators  # noqa: F401  (registers sim://)
from spotlab.drivers.selspot import SelspotDriver


class _Reads:
    def __init__(self) -> None:
        self.sizes: list[int] = []

    def on_rx(self, stream: str, data: bytes, arrival_ns: int) -> None:
        self.sizes.append(len(data))

    def on_tx(self, stream: str, data: bytes, sent_ns: int) -> None:
        pass

    def on_event(self, stream: str, kind: str, detail: dict[str, object], t_ns: int) -> None:
        pass


def test_reads_at_2_mbaud_carry_about_a_millisecond_of_bytes() -> None:
    reads = _Reads()
    driver = SelspotDriver("sim://selspot?cameras=4&leds=32", cameras=4, leds=32, rate_hz=200)
    driver.add_tap(reads)
    with driver:
        frames = 0
        while frames < 100:
            block = driver.recv(timeout=2.0)
            assert block is not None
            frames += len(block)
    streaming = reads.sizes[-50:]
    mean = sum(streaming) / len(streaming)
    # 2 Mbaud carries 200 bytes per ms; reads that returned a few bytes each made the
    # reader spin and the journal grow sevenfold in record headers.
    assert mean >= 100, streaming
