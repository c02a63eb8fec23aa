"""The picture of a wand calibration's quality report (PNG), drawn with matplotlib.

One panel per camera: the wand's image points coloured by their residual, rejected
ones marked, the reference object's markers where the rig projects them, axes in the
image's own unit (px, or detector counts for a PSD); then the rig from above with the
wand positions and the reference object (mm), and the histogram of wand length errors.
Panels sit on one grid (constrained layout), so none overlaps another.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from spotlab.calibration._rays import intersect
from spotlab.calibration.report import wand_lengths
from spotlab.geometry import Rig

__all__ = ["write_report_figure"]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


def _camera_panel(
    ax: Any,
    cam: Any,
    uv: FloatArray,
    res: FloatArray,
    bad: FloatArray,
    frame_uv: FloatArray | None,
    stats: dict[str, Any],
    units: str,
    vmax: float,
) -> Any:
    sc = ax.scatter(
        uv[:, 0], uv[:, 1], c=res, s=1, vmin=0, vmax=vmax, cmap="viridis", rasterized=True
    )
    if len(bad):
        ax.scatter(bad[:, 0], bad[:, 1], s=6, c="red", marker="x", label="rejected")
    if frame_uv is not None and np.isfinite(frame_uv).any():
        ax.plot(frame_uv[:, 0], frame_uv[:, 1], "s", ms=3, mfc="none", mec="C3", label="L-frame")
    w, h = cam.size
    ax.set_xlim(0, w)
    ax.set_ylim(h, 0)
    ax.set_aspect("equal")
    ax.set_xlabel(f"u ({units})", fontsize=7)
    ax.set_ylabel(f"v ({units})", fontsize=7)
    lens = stats.get("distortion", {}).get("fitted")
    ax.set_title(
        f"{cam.name}: RMS {stats['reprojection_rms_px']:.2f} {units}, "
        f"{100 * stats['image_coverage']:.0f} % covered\n"
        f"lens terms: {', '.join(lens) if lens else 'none'}",
        fontsize=7,
    )
    ax.tick_params(labelsize=6)
    if len(bad) or frame_uv is not None:
        ax.legend(fontsize=5, loc="lower right", markerscale=1.5)
    return sc


def write_report_figure(
    rig: Rig,
    wand: FloatArray,
    wand_residuals: FloatArray,
    inliers: BoolArray,
    report: dict[str, Any],
    path: str | Path,
    *,
    frame_points: FloatArray | None = None,
) -> Path:
    """Write the calibration's picture (PNG).

    Parameters
    ----------
    rig : Rig
        Calibrated cameras.
    wand : ndarray, shape (F, C, 2, 2)
        Wand image points (image units), NaN where unseen.
    wand_residuals : ndarray, shape (F, C, 2, 2)
        Reprojection residuals (image units).
    inliers : ndarray of bool, shape (F, C, 2)
        Observations kept.
    report : dict
        :func:`spotlab.calibration.report.quality_report` (``image_units`` names the
        unit of the image axes; ``px`` if absent).
    path : str or Path
        Output file (``.png``).
    frame_points : ndarray, shape (P, 3), optional
        The reference object's markers (mm), drawn in each image and from above.

    Returns
    -------
    Path
        The file written.
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    from matplotlib.figure import Figure

    units = str(report.get("image_units", "px"))
    C = len(rig)
    cols = min(C, 4)
    cam_rows = -(-C // cols)
    fig = Figure(figsize=(3.4 * cols, 3.3 * cam_rows + 3.4), layout="constrained")
    grid = fig.add_gridspec(cam_rows + 1, 2 * cols)
    norm_res = np.linalg.norm(wand_residuals, axis=-1)
    vmax = float(np.nanpercentile(norm_res[inliers], 99)) if np.any(inliers) else 1.0
    points = None if frame_points is None or len(frame_points) == 0 else frame_points
    cam_axes, sc = [], None
    for c, cam in enumerate(rig):
        ax = fig.add_subplot(grid[c // cols, 2 * (c % cols) : 2 * (c % cols) + 2])
        seen = np.all(np.isfinite(wand[:, c]), axis=-1)
        sc = _camera_panel(
            ax,
            cam,
            wand[:, c][inliers[:, c]],
            norm_res[:, c][inliers[:, c]],
            wand[:, c][~inliers[:, c] & seen],
            None if points is None else cam.project(points),
            report["cameras"][c],
            units,
            vmax,
        )
        cam_axes.append(ax)
    if sc is not None:
        fig.colorbar(sc, ax=cam_axes, shrink=0.8, label=f"residual ({units})")

    ax = fig.add_subplot(grid[cam_rows, 0:cols])
    centres = np.array([cam.center for cam in rig])
    F = wand.shape[0]
    X, _ = intersect(
        list(rig),
        np.where(inliers[..., None], wand, np.nan).transpose(1, 0, 2, 3).reshape(C, F * 2, 2),
    )
    ax.scatter(X[:, 0], X[:, 1], s=0.5, c="0.6", rasterized=True, label="wand ends")
    ax.scatter(centres[:, 0], centres[:, 1], marker="^", c="C3", label="cameras")
    for cam, pos in zip(rig, centres, strict=True):
        ax.annotate(cam.name, pos[:2], fontsize=7)
    if points is not None:
        for p in points[1:]:
            ax.plot([points[0, 0], p[0]], [points[0, 1], p[1]], "-", c="C1", lw=1.5)
        ax.plot(points[:, 0], points[:, 1], "o", ms=3, c="C1", label="L-frame")
    ax.set_aspect("equal")
    ax.set_xlabel("x (mm)", fontsize=7)
    ax.set_ylabel("y (mm)", fontsize=7)
    ax.set_title(f"rig from above (world frame: {report.get('world', 'reference object')})",
                 fontsize=8)  # fmt: skip
    ax.tick_params(labelsize=6)
    ax.legend(fontsize=6, loc="best")

    ax = fig.add_subplot(grid[cam_rows, cols : 2 * cols])
    lengths = wand_lengths(rig, wand, inliers)
    nominal = report["wand"]["nominal_mm"]
    ax.hist(lengths[np.isfinite(lengths)] - nominal, bins=50, color="C0")
    ax.set_xlabel("wand length error (mm)", fontsize=7)
    ax.set_ylabel("frames", fontsize=7)
    ax.set_title(
        f"wand length: SD {report['wand']['sd_mm']:.3f} mm, verdict {report['verdict']['grade']}",
        fontsize=8,
    )
    ax.tick_params(labelsize=6)
    out = Path(path)
    fig.savefig(out, dpi=110)
    return out
