"""The live pipeline: image2d frames to 3-D points in the reader thread, with latency.

See ``docs/live.md``.
"""

from spotlab.acquisition.live.readings import (
    FLAG_SATURATED,
    PSD_MAX_COUNT,
    is_psd_counts,
    pixels,
    usable_counts,
)

__all__ = ["FLAG_SATURATED", "PSD_MAX_COUNT", "is_psd_counts", "pixels", "usable_counts"]
