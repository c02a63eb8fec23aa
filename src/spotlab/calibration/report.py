"""Quality report of a rig calibration: residuals, wand length, coverage, a verdict, a PNG.

The figures a lab checks before trusting a calibration (METHODS.md, "Quality report"):
per camera reprojection RMS (px); the wand length triangulated freely from each frame
(both ends independently, so the known length is not imposed) with its mean, standard
deviation and largest error (mm); how much of each image and of the volume the wand
covered; and a plain verdict with its reasons.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from spotlab.calibration._rays import intersect
from spotlab.geometry import Rig

__all__ = [
    "VERDICT_LIMITS",
    "VERDICT_WIDTH",
    "image_coverage",
    "lens_report",
    "quality_report",
    "wand_lengths",
]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

#: Verdict thresholds: (reprojection RMS in px of a 1280 px wide image, wand SD as a
#: fraction of its length, image coverage fraction) for "good" and for "acceptable".
#: The RMS limit scales with the image width (``width / 1280``): 0.5 px on a 1280 px
#: camera is the same fraction of the field as 1.6 counts on a 4096-count PSD.
VERDICT_LIMITS = {"good": (0.5, 0.002, 0.4), "acceptable": (1.5, 0.01, 0.2)}
#: Image width (px) at which the RMS limits of :data:`VERDICT_LIMITS` hold as written.
VERDICT_WIDTH = 1280

_GRID = (16, 12)


def image_coverage(uv: FloatArray, size: tuple[int, int]) -> float:
    """Fraction of a 16 x 12 grid of image cells holding at least one observation."""
    uv = uv[np.all(np.isfinite(uv), axis=-1)]
    if uv.size == 0:
        return 0.0
    w, h = size
    i = np.clip((uv[:, 0] / w * _GRID[0]).astype(int), 0, _GRID[0] - 1)
    j = np.clip((uv[:, 1] / h * _GRID[1]).astype(int), 0, _GRID[1] - 1)
    return float(np.unique(i * _GRID[1] + j).size / (_GRID[0] * _GRID[1]))


def _rms(r: FloatArray) -> float:
    sq = np.sum(r * r, axis=-1)
    sq = sq[np.isfinite(sq)]
    return float(np.sqrt(np.mean(sq) / 2.0)) if sq.size else float("nan")


def wand_lengths(rig: Rig, wand: FloatArray, inliers: BoolArray) -> FloatArray:
    """Freely triangulated wand lengths (F,) (mm), NaN where an end has < 2 views."""
    F, C = wand.shape[:2]
    uv = np.where(inliers[..., None], wand, np.nan).transpose(1, 0, 2, 3).reshape(C, F * 2, 2)
    X, _ = intersect(list(rig), uv)
    ends = X.reshape(F, 2, 3)
    return np.linalg.norm(ends[:, 1] - ends[:, 0], axis=1)


def quality_report(
    rig: Rig,
    wand: FloatArray,
    wand_length: float,
    wand_residuals: FloatArray,
    frame_residuals: FloatArray,
    inliers: BoolArray,
    units: str = "px",
) -> dict[str, Any]:
    """Quality figures of a wand calibration.

    Parameters
    ----------
    rig : Rig
        Calibrated cameras.
    wand : ndarray, shape (F, C, 2, 2)
        Wand image points (px), NaN where unseen.
    wand_length : float
        Nominal wand length (mm).
    wand_residuals : ndarray, shape (F, C, 2, 2)
        Reprojection residuals (px) of the adjusted wand ends.
    frame_residuals : ndarray, shape (C, P, 2)
        Residuals (px) of the reference object's markers.
    inliers : ndarray of bool, shape (F, C, 2)
        Observations kept after outlier rejection.
    units : str
        Name of the image unit (``"px"``, or ``"counts"`` for a PSD detector); the
        report's ``*_px`` figures are in this unit (``report["image_units"]``).

    Returns
    -------
    dict
        ``cameras`` (list, per camera: name, reprojection_rms_px, frame_rms_px,
        observations, rejected, image_coverage), ``reprojection_rms_px``, ``wand``
        (nominal_mm, frames, mean_mm, sd_mm, max_error_mm, rms_error_mm),
        ``volume`` (min_mm, max_mm, filled_fraction) and ``verdict`` (grade, reasons).
        Every value is a plain float, int, str or list (JSON-safe).
    """
    seen = np.all(np.isfinite(wand), axis=-1)
    res_in = np.where(inliers[..., None], wand_residuals, np.nan)
    cameras = []
    for c, cam in enumerate(rig):
        cameras.append(
            {
                "name": cam.name,
                "reprojection_rms_px": _rms(res_in[:, c]),
                "frame_rms_px": _rms(frame_residuals[c]),
                "observations": int(np.count_nonzero(inliers[:, c])),
                "rejected": int(np.count_nonzero(seen[:, c] & ~inliers[:, c])),
                "image_coverage": image_coverage(wand[:, c].reshape(-1, 2), cam.size),
                "image_width": int(cam.size[0]),
            }
        )
    lengths = wand_lengths(rig, wand, inliers)
    lengths = lengths[np.isfinite(lengths)]
    err = lengths - wand_length
    wand_stats = {
        "nominal_mm": float(wand_length),
        "frames": int(lengths.size),
        "mean_mm": float(np.mean(lengths)) if lengths.size else float("nan"),
        "sd_mm": float(np.std(lengths, ddof=1)) if lengths.size > 1 else float("nan"),
        "max_error_mm": float(np.max(np.abs(err))) if lengths.size else float("nan"),
        "rms_error_mm": float(np.sqrt(np.mean(err**2))) if lengths.size else float("nan"),
    }
    F = wand.shape[0]
    X, _ = intersect(
        list(rig),
        np.where(inliers[..., None], wand, np.nan)
        .transpose(1, 0, 2, 3)
        .reshape(len(rig), F * 2, 2),
    )
    X = X[np.all(np.isfinite(X), axis=1)]
    volume: dict[str, Any] = {"min_mm": [], "max_mm": [], "filled_fraction": 0.0}
    if len(X):
        lo, hi = X.min(axis=0), X.max(axis=0)
        cells = np.clip(((X - lo) / np.maximum(hi - lo, 1e-9) * 8).astype(int), 0, 7)
        volume = {
            "min_mm": lo.tolist(),
            "max_mm": hi.tolist(),
            "filled_fraction": float(np.unique(cells @ [64, 8, 1]).size / 512),
        }
    overall = _rms(res_in)
    return {
        "cameras": cameras,
        "reprojection_rms_px": overall,
        "wand": wand_stats,
        "volume": volume,
        "image_units": units,
        "verdict": _verdict(cameras, wand_stats, units),
    }


def _verdict(cameras: list[dict[str, Any]], wand: dict[str, Any], units: str) -> dict[str, Any]:
    """Grade ``good``, ``acceptable`` or ``poor`` with the reasons for anything less."""
    reasons: list[str] = []
    grade = "good"
    for level in ("good", "acceptable"):
        rms_max, sd_frac, cover_min = VERDICT_LIMITS[level]
        failed = []
        for cam in cameras:
            limit = rms_max * cam["image_width"] / VERDICT_WIDTH
            if not cam["reprojection_rms_px"] <= limit:
                failed.append(
                    f"{cam['name']}: reprojection RMS {cam['reprojection_rms_px']:.3g} {units} "
                    f"> {limit:.3g} {units}"
                )
            if not cam["image_coverage"] >= cover_min:
                failed.append(
                    f"{cam['name']}: the wand covered {100 * cam['image_coverage']:.0f} % of "
                    f"the image (< {100 * cover_min:.0f} %): wave it nearer the image's "
                    "edges and corners"
                )
        if not wand["sd_mm"] <= sd_frac * wand["nominal_mm"]:
            failed.append(
                f"wand length SD {wand['sd_mm']:.3g} mm > {100 * sd_frac:.2g} % of "
                f"{wand['nominal_mm']:.4g} mm"
            )
        if not failed:
            break
        reasons = failed
        grade = "acceptable" if level == "good" else "poor"
    return {"grade": grade, "reasons": reasons}


def lens_report(report: dict[str, Any], mode: str, choices: Sequence[Any]) -> None:
    """Add to ``report["cameras"][c]["distortion"]`` the lens terms fitted, why, what next.

    Parameters
    ----------
    report : dict
        A :func:`quality_report`, changed in place.
    mode : str
        ``"auto"``, ``"none"``, ``"radial"``, ``"full"`` or ``"terms"`` (a given list).
    choices : sequence of LensChoice
        Per camera (``calibration._lens_terms``): ``terms``, ``edge_sd`` (units of the
        image noise), ``reason``, ``limited_by``.

    Notes
    -----
    Each camera gets ``fitted`` (list of term names), ``mode``, ``edge_sd_noise`` and
    ``edge_sd_px`` (largest SD of the modelled distortion over the image, in noise
    units and in px at the camera's reprojection RMS), ``limited_by``, ``reason`` and
    ``advice``; ``report["distortion_mode"]`` is ``mode``.
    """
    report["distortion_mode"] = mode
    for cam, ch in zip(report["cameras"], choices, strict=True):
        sd = float(ch.edge_sd)
        advice = ""
        if ch.limited_by == "coverage":
            advice = (
                "wave the wand nearer this camera's image edges and corners to fit more "
                "terms, or force them with --distortion radial|full"
            )
        elif ch.limited_by == "conditioning":
            advice = (
                "the data do not show the other terms (they may be negligible for this "
                "lens); if the lens needs them, wave the wand longer near this camera's "
                "image edges, or force them with --distortion radial|full"
            )
        elif ch.limited_by == "inversion":
            advice = "cover more of the image so that the lens model holds to its edges"
        elif ch.limited_by == "chosen" and not sd <= 1.0:
            advice = (
                f"the terms asked for are poorly determined here (distortion at the image "
                f"edge uncertain by {sd:.3g} x the noise): use --distortion auto"
            )
        cam["distortion"] = {
            "fitted": list(ch.terms),
            "mode": mode,
            "edge_sd_noise": sd if np.isfinite(sd) else None,
            "edge_sd_px": sd * cam["reprojection_rms_px"] if np.isfinite(sd) else None,
            "limited_by": ch.limited_by,
            "reason": ch.reason or "every term fitted",
            "advice": advice,
        }
