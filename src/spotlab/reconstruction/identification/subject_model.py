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
labels do not widen it), widened by ``margin_mm``.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from spotlab.core.errors import ReconstructionError
from spotlab.reconstruction.identification.model import Link, MarkerModel, Segment
from spotlab.reconstruction.identification.template import Template, TemplateFit

__all__ = ["FIRST_MARGIN_MM", "LEARN_MARGIN_MM", "first_model", "learn_model", "static_pose"]

FloatArray = NDArray[np.float64]

#: Widening of M0's link ranges each way (mm): soft tissue and the static trial's sway.
FIRST_MARGIN_MM = 15.0
#: Widening of the learnt link ranges each way (mm).
LEARN_MARGIN_MM = 5.0
#: Percentiles of the distances seen left out at each end of a learnt range.
TRIM_PERCENT = 0.5
#: Frames a link must be seen in, in the ROM trial, for its range to be learnt.
MIN_LINK_FRAMES = 20


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
    return template.model(
        static_pose(points, fit, template), scale=fit.scale, margin_mm=margin_mm
    )


def learn_model(
    model: MarkerModel,
    positions: Any,
    *,
    margin_mm: float = LEARN_MARGIN_MM,
    min_frames: int = MIN_LINK_FRAMES,
    trim_percent: float = TRIM_PERCENT,
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
    min_frames : int
        A link seen (both markers labelled) in fewer frames keeps ``model``'s range.
    trim_percent : float
        The range learnt runs from this percentile of the distances seen to 100 minus
        it: a few wrong labels in the trial do not widen it.

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
    links = []
    for k in model.links:
        d = np.linalg.norm(X[:, k.a] - X[:, k.b], axis=1)
        d = d[np.isfinite(d)]
        if d.size >= min_frames:
            lo, hi = np.percentile(d, [trim_percent, 100.0 - trim_percent])
            links.append(Link(k.a, k.b, max(0.0, float(lo) - margin_mm), float(hi) + margin_mm))
        else:
            links.append(k)
    return MarkerModel(model.labels, tuple(segments), tuple(links))
