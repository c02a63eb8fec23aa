"""What every MCS-1 configuration derives from its frame rate and frame size.

A family configuration (a frozen dataclass with ``rate_mhz``) derives from
:class:`LineLoad` and defines ``frame_bytes``; it gets ``rate_hz``,
``line_bits_per_s`` and the ``START:`` bandwidth rule :meth:`LineLoad.fits`
(mcs1.md: ``rate * bytes * 10 <= 0.8 * baud``, 10 bit times a byte).
"""

from __future__ import annotations


class LineLoad:
    """Frame rate and line load of an MCS-1 stream (mixin of the family configurations).

    Attributes
    ----------
    rate_mhz : int
        Frame rate in mHz (the ``RATE`` argument).
    """

    rate_mhz: int

    @property
    def frame_bytes(self) -> int:
        """Bytes of one data frame (the family defines it)."""
        raise NotImplementedError

    @property
    def rate_hz(self) -> float:
        """Frame rate in Hz."""
        return self.rate_mhz / 1000

    @property
    def line_bits_per_s(self) -> float:
        """Bits per second the stream occupies on the line (10 bit times a byte)."""
        return self.rate_mhz * self.frame_bytes * 10 / 1000

    def fits(self, baud: int) -> bool:
        """Whether the stream fits ``baud`` with 20 % to spare (the ``START:`` check)."""
        # rate * bytes * 10 <= 0.8 * baud, with rate in mHz: rate_mhz * bytes <= 80 * baud.
        return self.rate_mhz * self.frame_bytes <= 80 * baud
