"""Clock models: per-device maps of device ticks to session seconds, and their fitting.

Numerics only (numpy, scipy; spotlab.kinematics for the smoothing spline): no threads,
no devices. See docs/synchronisation.md, section "Clock models".
"""

from spotlab.acquisition.clocks.dejitter import ArrivalDejitter, DejitterResult, dejitter_arrivals
from spotlab.acquisition.clocks.edges import EdgeClockEstimator, fit_edges
from spotlab.acquisition.clocks.linefit import LineFit, fit_line, robust_sd
from spotlab.acquisition.clocks.model import ClockEvent, ClockModel, ClockSegment
from spotlab.acquisition.clocks.pairs import fit_pairs
from spotlab.acquisition.clocks.probes import (
    ProbePairs,
    fit_probes,
    min_rtt_per_window,
    probe_pairs,
)
from spotlab.acquisition.clocks.refine import RefinedClock, ResidualSpline, refine_model
from spotlab.acquisition.clocks.steps import find_steps
from spotlab.acquisition.clocks.xdf import (
    XdfStreamClock,
    fit_xdf_offsets,
    load_xdf_clocks,
)

__all__ = [
    "ArrivalDejitter",
    "ClockEvent",
    "ClockModel",
    "ClockSegment",
    "DejitterResult",
    "EdgeClockEstimator",
    "LineFit",
    "ProbePairs",
    "RefinedClock",
    "ResidualSpline",
    "XdfStreamClock",
    "dejitter_arrivals",
    "find_steps",
    "fit_edges",
    "fit_line",
    "fit_pairs",
    "fit_probes",
    "fit_xdf_offsets",
    "load_xdf_clocks",
    "min_rtt_per_window",
    "probe_pairs",
    "refine_model",
    "robust_sd",
]
