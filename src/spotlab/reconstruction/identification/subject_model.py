"""A new subject's marker models: the first from a template fit, the final from a ROM trial.

:func:`first_model` makes the subject's first model M0 from a static trial: the
template's structure (segments, links) with the subject's own static coordinates for
the segments (markers the static trial missed take the fitted template's place), and
the template's link ranges scaled to the subject and placed about the subject's own
static distances (:meth:`Template.model`). M0 labels a range-of-motion (ROM) trial
(:class:`~spotlab.reconstruction.identification.Identifier`), and :func:`learn_model`
learns the final model from those labelled trajectories: segment layouts averaged over
the trial (:meth:`MarkerModel.from_trajectories` with the template's segments), each
link's range the one seen in the trial (its 0.5-99.5 percentiles: a few wrong
labels do not widen it), widened by ``margin_mm`` and a tenth of its width.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from spotlab.core.errors import ReconstructionError
from spotlab.geometry import Rig
from spotlab.reconstruction.identification.blobs import BlobFrame
from spotlab.reconstruction.identification.identifier import Identifier
from spotlab.reconstruction.identification.model import Link, MarkerModel, Segment
from spotlab.reconstruction.identification.template import Template, TemplateFit, fit_template

__all__ = [
    "FIRST_MARGIN_MM",
    "LEARN_MARGIN_MM",
    "first_model",
    "label_trial",
    "learn_model",
    "static_pose",
    "subject_template",
]

FloatArray = NDArray[np.float64]

#: Widening of M0's link ranges each way (mm): soft tissue and the static trial's sway.
FIRST_MARGIN_MM = 15.0
#: Widening of the learnt link ranges each way: this (mm) plus ``LEARN_SPREAD_MARGIN``
#: times the range's own width. A wide range (a wrist to the other thigh) is one the
#: ROM did not fill: another motion goes past its ends (a walk by 10-30 mm on links
#: 100-300 mm wide, measured on subject 5), while a narrow range is a near-rigid pair.
LEARN_MARGIN_MM = 5.0
LEARN_SPREAD_MARGIN = 0.1
#: Links whose learnt range starts beyond this (mm) are long (across the body) and take
#: ``LEARN_SPREAD_MARGIN``; shorter ones tell nearby markers apart and keep theirs tight.
LONG_LINK_MM = 300.0
#: Percentiles of the distances seen left out at each end of a learnt range.
TRIM_PERCENT = 0.5
#: Other pairs whose distance varies less than this in the ROM trial become links (mm).
LINK_SPREAD_MM = 60.0
#: Frames a link must be seen in, in the ROM trial, for its range to be learnt.
MIN_LINK_FRAMES = 20
#: A ROM trial's static pose is looked for in its first frames, every few frames.
START_SEARCH_FRAMES = 300
START_SEARCH_STEP = 5
#: A searched frame fitting the static pose within this RMS (mm) ends the search.
START_GOOD_RMS_MM = 5.0
#: Largest RMS (mm) of the subject's own static pose fitted to a frame: its markers sit
#: where the static trial saw them, give or take sway and soft tissue, far closer than a
#: generic template's (an accepted fit 25 mm off had swapped the foot's markers; frames
#: in the pose fit within 3-5 mm).
SUBJECT_MAX_RMS_MM = 10.0


def static_pose(points: Any, fit: TemplateFit, template: Template) -> FloatArray:
    """The subject's static marker positions (M, 3) mm in the template's label order:
    the matched point of each marker, the fitted template's position where none matched."""
    P = np.asarray(points, dtype=np.float64)
    X = fit.transform(template.neutral_mm)
    ok = fit.point_of >= 0
    X[ok] = P[fit.point_of[ok]]
    return np.asarray(X)


def first_model(
    points: Any, fit: TemplateFit, template: Template, *, margin_mm: float = FIRST_MARGIN_MM
) -> MarkerModel:
    """The subject's first model M0 from its static cloud and the template fit.

    Parameters
    ----------
    points : array_like, shape (N, 3)
        The static cloud :func:`.fit_template` was given (mm).
    fit : TemplateFit
    template : Template
    margin_mm : float
        Widening of every link range, each way (mm).

    Returns
    -------
    MarkerModel
    """
    return template.model(static_pose(points, fit, template), scale=fit.scale, margin_mm=margin_mm)


def subject_template(
    points: Any, fit: TemplateFit, template: Template, model: MarkerModel
) -> Template:
    """The subject's own static pose as a template (its body frame, its own size), with
    ``model``'s structure: what :func:`label_trial` fits to a trial's first frame."""
    X = static_pose(points, fit, template)
    body = (X - fit.translation) @ fit.rotation  # rotation only: the subject's own size
    segments = {s.name: tuple(model.labels[m] for m in s.markers) for s in model.segments}
    return Template(
        f"{template.name} (subject)", model.labels, body, segments, model.links,
        f"static pose fitted to template {template.name!r}",
        max_rms_mm=SUBJECT_MAX_RMS_MM,
    )  # fmt: skip


def label_trial(
    rig: Rig,
    frames: Iterable[tuple[BlobFrame, Any]],
    model: MarkerModel,
    start: Template | None = None,
    *,
    search_frames: int = START_SEARCH_FRAMES,
    search_step: int = START_SEARCH_STEP,
    **identifier_options: Any,
) -> tuple[FloatArray, TemplateFit | None]:
    """Label a trial with ``model``: a ROM trial, to learn the final model from.

    Parameters
    ----------
    rig : Rig
    frames : iterable of (BlobFrame, unusable)
        Each frame's blobs and its unusable cameras (or None).
    model : MarkerModel
    start : Template, optional
        The subject's static pose (:func:`subject_template`). The trial holds it
        somewhere in its first ``search_frames`` frames (the subject stands in it when the
        recording starts, or soon after): every ``search_step``-th of those frames is
        fitted (:func:`.fit_template`, within the template's own bounds) until one fits
        within ``START_GOOD_RMS_MM``, the best fit's
        points are labelled and the labels carried by tracking forward to the trial's end
        and backward to its first frame. The model's links alone cannot tell apart
        markers close together on a cold start. None: the identifier alone.
    search_frames, search_step : int
        Where the static pose is looked for, in frames.
    **identifier_options
        Passed to :class:`Identifier`.

    Returns
    -------
    positions : ndarray, shape (F, M, 3)
        Labelled positions (mm), NaN where a marker was not labelled.
    fit : TemplateFit or None
        The fit of ``start`` to the frame it fitted best (``fit.frame``).

    Raises
    ------
    ReconstructionError
        When no frame searched fits ``start`` (the subject never stood in the static
        pose there), or the trial has no frames.
    """
    todo = list(frames)
    if not todo:
        raise ReconstructionError("the trial has no frames")
    if start is None:
        identify = Identifier(rig, model, **identifier_options)
        return np.stack([identify(*frame).points for frame in todo]), None
    fit = _find_static_pose(rig, todo, model, start, search_frames, search_step,
                            identifier_options)  # fmt: skip
    out: list[FloatArray | None] = [None] * len(todo)
    for order in (range(fit.frame, len(todo)), range(fit.frame, -1, -1)):
        identify = Identifier(rig, model, **identifier_options)
        for k, f in enumerate(order):
            result = identify(*todo[f])
            if k == 0:
                identify.seed_labels(fit.marker_of)
                result = identify(*todo[f])  # the frame again, its labels checked
            out[f] = result.points
    return np.stack([x for x in out if x is not None]), fit


def _find_static_pose(
    rig: Rig,
    frames: list[tuple[BlobFrame, Any]],
    model: MarkerModel,
    start: Template,
    search_frames: int,
    search_step: int,
    identifier_options: dict[str, Any],
) -> TemplateFit:
    """The best fit of the static pose ``start`` among the searched frames, with the
    frame it came from (its points those of a cold identifier at that frame)."""
    identify = Identifier(rig, model, **identifier_options)
    best: tuple[float, int] | None = None
    refusal = ""
    step = max(1, search_step)
    for f in range(min(len(frames), max(1, search_frames))):
        identify(*frames[f])
        if f % step:
            continue
        try:
            rms = fit_template(identify.current_points(), start).rms_mm
        except ReconstructionError as exc:
            refusal = str(exc)
            continue
        if best is None or rms < best[0]:
            best = (rms, f)
        if rms <= START_GOOD_RMS_MM:
            break
    if best is None:
        raise ReconstructionError(
            f"the subject's static pose fits none of the trial's first {search_frames} "
            f"frames (every {step}th tried; the last: {refusal}); a ROM trial starts with "
            "the subject standing in the static pose"
        )
    cold = Identifier(rig, model, **identifier_options)
    cold(*frames[best[1]])
    return replace(fit_template(cold.current_points(), start), frame=best[1])


def learn_model(
    model: MarkerModel,
    positions: Any,
    *,
    margin_mm: float = LEARN_MARGIN_MM,
    spread_margin: float = LEARN_SPREAD_MARGIN,
    min_frames: int = MIN_LINK_FRAMES,
    trim_percent: float = TRIM_PERCENT,
    link_spread_mm: float | None = LINK_SPREAD_MM,
) -> MarkerModel:
    """The final model from trajectories labelled with ``model`` (a ROM trial).

    Parameters
    ----------
    model : MarkerModel
        The model the trajectories were labelled with (its structure is kept).
    positions : array_like, shape (F, M, 3)
        Labelled positions (mm) in ``model``'s label order, NaN where unlabelled.
    margin_mm : float
        Widening of every learnt link range, each way (mm).
    spread_margin : float
        Further widening each way, as a fraction of the range's own width.
    min_frames : int
        A link seen (both markers labelled) in fewer frames keeps ``model``'s range.
    trim_percent : float
        The range learnt runs from this percentile of the distances seen to 100 minus
        it: a few wrong labels in the trial do not widen it.
    link_spread_mm : float or None
        Pairs of markers not on a common segment and not yet linked whose distance
        varied by less than this over the trial become links too (narrow ranges tell
        nearby points apart); None: the model's links only.

    Returns
    -------
    MarkerModel

    Raises
    ------
    ReconstructionError
        For trajectories of another shape, or a segment never labelled complete.
    """
    X = np.asarray(positions, dtype=np.float64)
    M = len(model.labels)
    if X.ndim != 3 or X.shape[1:] != (M, 3):
        raise ReconstructionError(f"positions must have shape (F, {M}, 3), got {X.shape}")
    segments = []
    for seg in model.segments:  # each layout learnt alone, as a model of its markers
        names = [model.labels[m] for m in seg.markers]
        alone = MarkerModel.from_trajectories(names, X[:, list(seg.markers)], {seg.name: names})
        segments.append(Segment(seg.name, seg.markers, alone.segments[0].coordinates))
    M = len(model.labels)
    a, b = np.triu_indices(M, 1)
    linked = np.zeros((M, M), dtype=bool)
    for k in model.links:
        linked[k.a, k.b] = linked[k.b, k.a] = True
    owner = model.segment_of
    links = []
    for i, j in zip(a, b, strict=True):
        if owner[i] >= 0 and owner[i] == owner[j]:
            continue
        d = np.linalg.norm(X[:, i] - X[:, j], axis=1)
        d = d[np.isfinite(d)]
        if d.size < min_frames:
            continue
        lo, hi = np.percentile(d, [trim_percent, 100.0 - trim_percent])
        if linked[i, j] or (link_spread_mm is not None and hi - lo < link_spread_mm):
            wide = margin_mm + (spread_margin * (hi - lo) if lo > LONG_LINK_MM else 0.0)
            links.append(Link(int(i), int(j), max(0.0, lo - wide), hi + wide))
            linked[i, j] = linked[j, i] = False  # done
    links.extend(k for k in model.links if linked[k.a, k.b])  # too rarely seen: kept
    return MarkerModel(model.labels, tuple(segments), tuple(links))
