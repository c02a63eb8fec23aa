"""The live pipeline: image2d frames to 3-D points in the reader thread, with latency;
labelled point3d streams (Qualisys, NatNet) passed through.

See ``docs/live.md``.
"""

from spotlab.acquisition.live.latency import LatencyStats, LatencySummary
from spotlab.acquisition.live.matching import FrameMatcher
from spotlab.acquisition.live.pipeline import ClockLike, LivePipeline, LiveStats
from spotlab.acquisition.live.readings import (
    FLAG_SATURATED,
    PSD_MAX_COUNT,
    is_psd_counts,
    pixels,
    usable_counts,
)
from spotlab.acquisition.live.replay import recorded_specs, replay_live
from spotlab.acquisition.live.results import LiveFrame, LslMarkers, MarkerPusher, PointRecorder

__all__ = [
    "FLAG_SATURATED",
    "PSD_MAX_COUNT",
    "ClockLike",
    "FrameMatcher",
    "LatencyStats",
    "LatencySummary",
    "LiveFrame",
    "LivePipeline",
    "LiveStats",
    "LslMarkers",
    "MarkerPusher",
    "PointRecorder",
    "is_psd_counts",
    "pixels",
    "recorded_specs",
    "replay_live",
    "usable_counts",
]
