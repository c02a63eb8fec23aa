"""A generic marker template, and its fit to a new subject's unlabelled static pose.

A :class:`Template` is a marker set's labels, its neutral standing pose (mm, in a body
frame: x forward, y left, z up, the floor at z = 0) and its marker model structure
(segments, distance links with ranges). Commercial systems label a new subject by
fitting such a template to a static trial and then refining it with a range-of-motion
trial; :func:`fit_template` does the first step on one unlabelled point cloud:

1. **Scale** from heights: the cloud's top over the template's (both stand on z = 0).
2. **Yaw** searched over the full circle (5° steps): the subject may face any way; the
   body's front and back differ (ASIS in front, PSIS behind, toes forward), which
   settles left and right. For each yaw the template is placed at the cloud's
   horizontal median and markers are assigned to points by the Hungarian algorithm
   with a cost cap (a marker farther than ``cap_mm`` from every point stays
   unmatched, and so does a point farther than that from every marker), the
   horizontal translation corrected twice.
3. **Refinement** of the three best yaws: a few rounds of similarity Procrustes
   (Umeyama 1991: rotation, scale, translation minimising the squared distances of
   the matched pairs) and reassignment; the round with the smallest capped cost wins.

The fit is refused (:class:`~spotlab.core.errors.ReconstructionError`) when fewer than
``min_matched`` of the template's markers find a point, or when the RMS residual of
the matched ones exceeds ``max_rms_mm``: the cloud is not a person standing in this
marker set's neutral pose.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from dataclasses import dataclass
from importlib import resources
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import linear_sum_assignment

from spotlab.core.errors import ReconstructionError
from spotlab.reconstruction.identification.model import Link, MarkerModel, Segment

__all__ = [
    "Template",
    "TemplateFit",
    "fit_template",
    "load_template",
    "shipped_templates",
    "similarity_procrustes",
]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]

#: Default bounds of an accepted fit: matched fraction of the template's markers, and
#: RMS residual (mm) of the matched ones after the similarity fit.
MIN_MATCHED = 0.6
MAX_RMS_MM = 30.0
#: Default cost cap of the assignment (mm): farther pairs are left unmatched.
CAP_MM = 80.0


@dataclass(frozen=True)
class Template:
    """A marker set's neutral pose and model structure.

    Attributes
    ----------
    name : str
    labels : tuple of str, length M
    neutral_mm : ndarray, shape (M, 3)
        Neutral standing pose (mm): x forward, y left, z up, floor at z = 0.
    segments : mapping of str to tuple of str
        Rigid clusters (3 or more markers each) by name.
    links : tuple of Link
        Distance links (indices into ``labels``) with their ranges (mm) for the
        template's body size.
    source : str
        Where the pose and structure come from.
    cap_mm, max_rms_mm : float
        The template's own bounds of :func:`fit_template` (mm): how far a subject's
        markers may sit from the fitted template and still be matched, and the largest
        RMS residual of an accepted fit. Real marker sets vary more between subjects and
        labs than the simulator's placement (``lower-limb``: 120 and 70 mm).
    """

    name: str
    labels: tuple[str, ...]
    neutral_mm: FloatArray
    segments: Mapping[str, tuple[str, ...]]
    links: tuple[Link, ...]
    source: str = ""
    cap_mm: float = CAP_MM
    max_rms_mm: float = MAX_RMS_MM

    def __post_init__(self) -> None:
        M = len(self.labels)
        if M < 3 or np.shape(self.neutral_mm) != (M, 3):
            raise ReconstructionError(
                f"template {self.name!r}: need 3 or more markers and a pose of shape (M, 3)"
            )
        if not np.isfinite(self.neutral_mm).all():
            raise ReconstructionError(f"template {self.name!r}: the neutral pose has gaps")
        self.model(self.neutral_mm)  # checks labels, segments and links

    def model(
        self, positions_mm: Any, *, scale: float = 1.0, margin_mm: float = 0.0
    ) -> MarkerModel:
        """The template's structure with a subject's own static coordinates.

        Segment layouts are the subject's (``positions_mm``). A link's range is the
        template's about its neutral distance, times ``scale``, placed about the
        subject's own distance of the two markers where both are given (marker
        placement differs from subject to subject), and widened by ``margin_mm`` each
        way.

        Parameters
        ----------
        positions_mm : array_like, shape (M, 3)
            The subject's static marker positions (mm), in the template's label order;
            NaN where missing (a link of a missing marker keeps the scaled range).
        scale : float
            Subject size over the template's.
        margin_mm : float
            Widening of every link range, each way (mm).

        Returns
        -------
        MarkerModel

        Raises
        ------
        ReconstructionError
            When a segment misses a marker in ``positions_mm``.
        """
        X = np.asarray(positions_mm, dtype=np.float64)
        if X.shape != self.neutral_mm.shape:
            raise ReconstructionError(f"positions must have shape {self.neutral_mm.shape}")
        index = {name: m for m, name in enumerate(self.labels)}
        segments = []
        for name, members in self.segments.items():
            unknown = [x for x in members if x not in index]
            if unknown:
                raise ReconstructionError(f"segment {name!r}: unknown markers {unknown}")
            m = [index[x] for x in members]
            if not np.isfinite(X[m]).all():
                raise ReconstructionError(f"segment {name!r} misses a marker in the pose")
            segments.append(Segment(name, tuple(m), X[m] - X[m].mean(axis=0)))
        T = self.neutral_mm
        links = []
        for k in self.links:
            d_t = float(np.linalg.norm(T[k.a] - T[k.b]))
            d_s = float(np.linalg.norm(X[k.a] - X[k.b]))
            d_s = d_s if np.isfinite(d_s) else scale * d_t
            lo = d_s + scale * (k.min_mm - d_t) - margin_mm
            hi = d_s + scale * (k.max_mm - d_t) + margin_mm
            links.append(Link(k.a, k.b, max(0.0, lo), max(0.0, hi)))
        return MarkerModel(self.labels, tuple(segments), tuple(links))

    def to_json(self) -> dict[str, Any]:
        """JSON-safe description (the layout of :meth:`save`)."""
        return {
            "name": self.name,
            "source": self.source,
            "frame": "x forward, y left, z up (mm), floor at z = 0",
            "labels": list(self.labels),
            "neutral_mm": np.round(self.neutral_mm, 2).tolist(),
            "segments": [{"name": n, "markers": list(m)} for n, m in self.segments.items()],
            "links": [
                {
                    "markers": [self.labels[k.a], self.labels[k.b]],
                    "range_mm": [round(k.min_mm, 2), round(k.max_mm, 2)],
                }
                for k in self.links
            ],
            "fit_bounds": {"cap_mm": self.cap_mm, "max_rms_mm": self.max_rms_mm},
        }

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write the template as JSON."""
        with open(path, "w", encoding="utf-8") as fh:
            json.dump(self.to_json(), fh, indent=1)
            fh.write("\n")

    @classmethod
    def from_json(cls, data: Mapping[str, Any], where: str = "template") -> Template:
        """Build from :meth:`to_json`'s layout; a malformed one is a ReconstructionError."""
        try:
            labels = tuple(str(x) for x in data["labels"])
            index = {name: m for m, name in enumerate(labels)}
            segments = {str(s["name"]): tuple(str(x) for x in s["markers"])
                        for s in data.get("segments", [])}  # fmt: skip
            links = tuple(
                Link(index[str(k["markers"][0])], index[str(k["markers"][1])],
                     float(k["range_mm"][0]), float(k["range_mm"][1]))
                for k in data.get("links", [])
            )  # fmt: skip
            return cls(
                str(data.get("name", "")), labels,
                np.asarray(data["neutral_mm"], dtype=np.float64), segments, links,
                str(data.get("source", "")),
                float(data.get("fit_bounds", {}).get("cap_mm", CAP_MM)),
                float(data.get("fit_bounds", {}).get("max_rms_mm", MAX_RMS_MM)),
            )  # fmt: skip
        except (ValueError, KeyError, TypeError, IndexError) as exc:
            raise ReconstructionError(f"{where}: not a marker template ({exc!r})") from None

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> Template:
        """Read a template written by :meth:`save`."""
        try:
            with open(path, encoding="utf-8") as fh:
                data = json.load(fh)
        except (OSError, ValueError) as exc:
            raise ReconstructionError(f"{path}: not a marker template ({exc})") from None
        return cls.from_json(data, str(path))


@dataclass(frozen=True)
class TemplateFit:
    """A template fitted to an unlabelled point cloud.

    Attributes
    ----------
    marker_of : ndarray of int, shape (N,)
        Template marker of each point, -1 for an unmatched point.
    point_of : ndarray of int, shape (M,)
        Point of each template marker, -1 where none matched.
    scale : float
        Template -> subject size.
    rotation : ndarray, shape (3, 3)
    translation : ndarray, shape (3,)
        ``point = scale * rotation @ template + translation`` (mm).
    yaw_deg : float
        Heading of the template's forward axis in the cloud's frame (deg, 0 = +x).
    residual_mm : ndarray, shape (M,)
        Distance of each matched marker's point from the fitted template (mm), NaN
        where unmatched.
    rms_mm : float
        RMS of the matched residuals (mm).
    matched : float
        Fraction of the template's markers matched.
    frame : int
        The trial frame whose points were fitted, where a trial was searched
        (:func:`~spotlab.reconstruction.identification.subject_model.label_trial`); 0
        otherwise.
    """

    marker_of: IntArray
    point_of: IntArray
    scale: float
    rotation: FloatArray
    translation: FloatArray
    yaw_deg: float
    residual_mm: FloatArray
    rms_mm: float
    matched: float
    frame: int = 0

    def labels(self, template: Template) -> list[str | None]:
        """Label of each point (None where unmatched)."""
        return [template.labels[m] if m >= 0 else None for m in self.marker_of]

    def transform(self, X: Any) -> FloatArray:
        """Template coordinates (..., 3) -> the cloud's frame (mm)."""
        return np.asarray(self.scale * np.asarray(X) @ self.rotation.T + self.translation)


def similarity_procrustes(A: FloatArray, B: FloatArray) -> tuple[float, FloatArray, FloatArray]:
    """Scale, rotation and translation with ``B ~ s R A + t`` (Umeyama 1991).

    Parameters
    ----------
    A, B : ndarray, shape (P, 3)
        Matched points (P >= 3, not all on a line).

    Returns
    -------
    s : float
    R : ndarray, shape (3, 3)
        A proper rotation (det +1).
    t : ndarray, shape (3,)
    """
    ma, mb = A.mean(axis=0), B.mean(axis=0)
    a, b = A - ma, B - mb
    U, S, Vt = np.linalg.svd(b.T @ a / A.shape[0])
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt)) or 1.0])
    R = U @ D @ Vt
    var_a = float((a * a).sum() / A.shape[0])
    s = float(np.trace(np.diag(S) @ D) / var_a) if var_a > 0 else 1.0
    return s, R, mb - s * R @ ma


def _rot_z(yaw: float) -> FloatArray:
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _assign(T: FloatArray, P: FloatArray, cap_mm: float) -> tuple[IntArray, float]:
    """Hungarian assignment of markers ``T`` (M, 3) to points ``P`` (N, 3), pairs farther
    than ``cap_mm`` left out: point index per marker (-1 unmatched) and capped cost."""
    D2 = ((T[:, None, :] - P[None, :, :]) ** 2).sum(axis=2)
    cap2 = cap_mm * cap_mm
    cost = np.concatenate([np.minimum(D2, 2 * cap2), np.full((T.shape[0], T.shape[0]), cap2)], 1)
    rows, cols = linear_sum_assignment(cost)
    point = np.full(T.shape[0], -1, dtype=np.intp)
    real = cols < P.shape[0]
    real[real] = D2[rows[real], cols[real]] < cap2
    point[rows[real]] = cols[real]
    matched = point >= 0
    cost_sum = D2[matched, point[matched]].sum() + cap2 * (~matched).sum()
    return point, float(cost_sum)


def fit_template(
    points: Any,
    template: Template,
    *,
    cap_mm: float | None = None,
    min_matched: float = MIN_MATCHED,
    max_rms_mm: float | None = None,
    yaw_step_deg: float = 5.0,
    rounds: int = 6,
) -> TemplateFit:
    """Fit ``template`` to an unlabelled static point cloud (see the module docstring).

    Parameters
    ----------
    points : array_like, shape (N, 3)
        Unlabelled points (mm), z up with the floor at z = 0; NaN rows are ignored. N
        may differ from the template's M (hidden markers, extra points).
    template : Template
    cap_mm : float, optional
        Largest distance of an assigned marker-point pair (mm); default the template's.
    min_matched : float
        Smallest accepted fraction of the template's markers matched.
    max_rms_mm : float, optional
        Largest accepted RMS residual of the matched markers (mm); default the
        template's.
    yaw_step_deg : float
        Step of the yaw search over the full circle (deg).
    rounds : int
        Procrustes + reassignment rounds per refined yaw.

    Returns
    -------
    TemplateFit

    Raises
    ------
    ReconstructionError
        For a bad cloud (shape, fewer than 3 points, nothing above the floor) or a fit
        beyond the bounds (too few matched markers, RMS too large).
    """
    cap_mm = template.cap_mm if cap_mm is None else cap_mm
    max_rms_mm = template.max_rms_mm if max_rms_mm is None else max_rms_mm
    P_all = np.asarray(points, dtype=np.float64)
    if P_all.ndim != 2 or P_all.shape[1] != 3:
        raise ReconstructionError(f"points must have shape (N, 3), got {P_all.shape}")
    finite = np.flatnonzero(np.isfinite(P_all).all(axis=1))
    P = P_all[finite]
    T = np.asarray(template.neutral_mm, dtype=np.float64)
    M = T.shape[0]
    if P.shape[0] < 3 or P[:, 2].max() <= 0:
        raise ReconstructionError(
            f"cannot fit template {template.name!r}: {P.shape[0]} points, need 3 or more "
            "above the floor"
        )
    s0 = float(np.clip(P[:, 2].max() / T[:, 2].max(), 0.5, 2.0))
    centre_p = np.median(P[:, :2], axis=0)
    centre_t = np.median(T[:, :2], axis=0)
    scored = []
    for yaw in np.deg2rad(np.arange(0.0, 360.0, yaw_step_deg)):
        R = _rot_z(yaw)
        t = np.zeros(3)
        t[:2] = centre_p - s0 * (R[:2, :2] @ centre_t)
        for _ in range(3):
            Y = s0 * T @ R.T + t
            point, cost = _assign(Y, P, cap_mm)
            ok = point >= 0
            if ok.any():
                t[:2] += (P[point[ok], :2] - Y[ok, :2]).mean(axis=0)
        scored.append((cost, yaw, t.copy()))
    scored.sort(key=lambda x: x[0])
    best: tuple[float, float, FloatArray, FloatArray, IntArray] | None = None
    for _, yaw, t in scored[:3]:
        s, R = s0, _rot_z(yaw)
        for _ in range(rounds):
            point, cost = _assign(s * T @ R.T + t, P, cap_mm)
            ok = point >= 0
            if best is None or cost < best[0]:
                best = (cost, s, R, t, point)
            if ok.sum() < 3:
                break
            s, R, t = similarity_procrustes(T[ok], P[point[ok]])
        point, cost = _assign(s * T @ R.T + t, P, cap_mm)
        if best is None or cost < best[0]:
            best = (cost, s, R, t, point)
    assert best is not None
    _, s, R, t, point = best
    ok = point >= 0
    residual = np.full(M, np.nan)
    residual[ok] = np.linalg.norm(s * T[ok] @ R.T + t - P[point[ok]], axis=1)
    rms = float(np.sqrt(np.mean(residual[ok] ** 2))) if ok.any() else float("inf")
    matched = float(ok.mean())
    if matched < min_matched or rms > max_rms_mm:
        raise ReconstructionError(
            f"the points do not fit template {template.name!r}: {ok.sum()} of {M} markers "
            f"matched (need {min_matched:.0%}), RMS {rms:.1f} mm (at most {max_rms_mm:g}); "
            "is this a person standing still in the neutral pose, with this marker set?"
        )
    point_of = np.where(ok, finite[np.maximum(point, 0)], -1).astype(np.intp)
    marker_of = np.full(P_all.shape[0], -1, dtype=np.intp)
    marker_of[point_of[ok]] = np.flatnonzero(ok)
    fwd = R @ np.array([1.0, 0.0, 0.0])
    return TemplateFit(
        marker_of=marker_of, point_of=point_of, scale=float(s), rotation=R,
        translation=np.asarray(t, dtype=np.float64),
        yaw_deg=float(np.degrees(np.arctan2(fwd[1], fwd[0])) % 360.0),
        residual_mm=residual, rms_mm=rms, matched=matched,
    )  # fmt: skip


def shipped_templates() -> list[str]:
    """Names of the templates shipped with spotlab (package data ``templates/*.json``)."""
    folder = resources.files(__package__ or "spotlab.reconstruction.identification")
    return sorted(
        f.name.removesuffix(".json")
        for f in folder.joinpath("templates").iterdir()
        if f.name.endswith(".json")
    )


def load_template(name_or_path: str | os.PathLike[str]) -> Template:
    """A shipped template by name (:func:`shipped_templates`), or a template JSON file.

    Raises
    ------
    ReconstructionError
        For a name that is neither a shipped template nor a file, or a malformed file.
    """
    text = os.fspath(name_or_path)
    if os.path.isfile(text):
        return Template.load(text)
    if text in shipped_templates():
        folder = resources.files(__package__ or "spotlab.reconstruction.identification")
        data = json.loads(folder.joinpath("templates", f"{text}.json").read_text("utf-8"))
        return Template.from_json(data, text)
    raise ReconstructionError(
        f"no template {text!r}: neither a file nor one of {', '.join(shipped_templates())}"
    )
