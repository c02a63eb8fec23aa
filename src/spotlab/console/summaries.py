"""The human-readable summaries of a reconstruction (``spotlab reconstruct`` and
``spotlab export``) on stdout."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from spotlab.processing.identification_passes import MAX_LOST_FRAMES

__all__ = ["print_blob_summary", "print_summary"]


def print_summary(summary: dict[str, Any], outputs: Sequence[Path]) -> None:
    """The human-readable summary of a reconstruction on stdout."""
    if summary.get("method") == "identification":
        print_blob_summary(summary, list(outputs))
        return
    rms = summary["rms_ray_px"]
    lost = summary.get("lost_frames")
    print(
        f"reconstructed {summary['frames']} frames x {summary['markers']} markers at "
        f"{summary['rate_hz']:g} Hz ({summary['method']}, {summary['cameras']} cameras)"
        + (f", {lost} frames lost in the recording" if lost else "")
    )
    print(
        f"  reconstructed      {100 * summary['reconstructed_fraction']:.1f} % of marker "
        f"samples ({summary['markers_reconstructed']} markers seen)"
    )
    print("  RMS ray residual   " + ("-" if rms is None else f"{rms:.3f} px"))
    for path in outputs:
        print(f"  wrote              {path}")


def print_blob_summary(summary: dict[str, Any], outputs: list[Path]) -> None:
    """The human-readable summary of a blob reconstruction on stdout."""
    rms = summary["rms_ray_px"]
    lost = summary["lost_frames"]
    print(
        f"identified {summary['frames']} frames x {summary['markers']} markers at "
        f"{summary['rate_hz']:g} Hz ({summary['cameras']} cameras)"
        + (f", {lost} frames lost in the recording" if lost else "")
    )
    print(
        f"  labelled           {100 * summary['labelled_fraction']:.2f} % of marker "
        f"samples ({summary['markers_reconstructed']} markers seen, "
        f"{summary['marker_gaps']} gaps)"
    )
    if summary.get("filled_backward") or summary.get("label_conflicts"):
        print(
            f"  backward pass      filled {summary['filled_backward']} marker samples, "
            f"dropped {summary['label_conflicts']} where the passes disagreed"
        )
    if summary.get("bridged"):
        print(
            f"  trajectories       filled {summary['bridged']} marker samples between "
            "two labels of one unbroken trajectory"
        )
    print(
        f"  rejected           {summary['ghosts_rejected']} reflection points, "
        f"{summary['unlabelled_per_frame']:g} unlabelled points per frame"
    )
    if summary["identification_restarts"]:
        print(
            f"  started afresh     {summary['identification_restarts']} times, after gaps "
            f"of more than {MAX_LOST_FRAMES} lost frame"
        )
    print("  RMS ray residual   " + ("-" if rms is None else f"{rms:.3f} px"))
    for name, counts in summary["camera_frames"].items():
        bad = {k: v for k, v in counts.items() if v}
        if bad:
            print(
                f"  {name:<18} "
                + ", ".join(f"{k.replace('_', ' ')} {v} frames" for k, v in bad.items())
            )
    for path in outputs:
        print(f"  wrote              {path}")
