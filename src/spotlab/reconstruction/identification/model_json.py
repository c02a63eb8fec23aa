"""A marker model's JSON file: what :meth:`MarkerModel.save` writes and ``load`` reads.

Markers are named by label everywhere in the file (segments, links, references), so a
file stays readable and a label's index is the file's business only.
"""

from __future__ import annotations

import json
import os
from typing import TYPE_CHECKING, Any

import numpy as np

from spotlab.core.errors import ReconstructionError
from spotlab.reconstruction.identification.handedness import Reference
from spotlab.reconstruction.identification.model_parts import Link, Segment

if TYPE_CHECKING:
    from spotlab.reconstruction.identification.model import MarkerModel

__all__ = ["ModelFields", "model_to_json", "read_model_fields", "write_model"]

#: What a file gives a MarkerModel: labels, segments, links, tolerance_mm,
#: link_spread_mm, references.
ModelFields = tuple[
    tuple[str, ...], tuple[Segment, ...], tuple[Link, ...], float | None, float | None,
    tuple[Reference, ...],
]  # fmt: skip


def model_to_json(model: MarkerModel) -> dict[str, Any]:
    """JSON-safe description of ``model`` (the file layout); ``references`` only when
    the model has some."""
    labels = model.labels
    out: dict[str, Any] = {
        "labels": list(labels),
        "tolerance_mm": model.tolerance_mm,
        "link_spread_mm": model.link_spread_mm,
        "segments": [
            {
                "name": seg.name,
                "markers": [labels[m] for m in seg.markers],
                "coordinates_mm": seg.coordinates.round(4).tolist(),
            }
            for seg in model.segments
        ],
        "links": [
            {
                "markers": [labels[k.a], labels[k.b]],
                "range_mm": [round(k.min_mm, 4), round(k.max_mm, 4)],
            }
            for k in model.links
        ],
    }
    if model.references:
        out["references"] = [
            {
                "segment": model.segments[r.segment].name,
                "marker": labels[r.marker],
                "direction": r.direction.round(6).tolist(),
                "spread_deg": round(r.spread_deg, 4),
                "triple": [labels[m] for m in r.triple],
                "side": r.side,
            }
            for r in model.references
        ]
    return out


def write_model(model: MarkerModel, path: str | os.PathLike[str]) -> None:
    """Write ``model`` as JSON to ``path``."""
    with open(path, "w", encoding="utf-8") as fh:
        json.dump(model_to_json(model), fh, indent=1)


def read_model_fields(path: str | os.PathLike[str]) -> ModelFields:
    """The fields of the model in a file written by :func:`write_model`; a malformed
    file is a ReconstructionError naming it."""
    try:
        with open(path, encoding="utf-8") as fh:
            data = json.load(fh)
        labels = tuple(str(x) for x in data["labels"])
        index = {name: m for m, name in enumerate(labels)}
        segments = tuple(
            Segment(
                str(s["name"]),
                tuple(index[str(x)] for x in s["markers"]),
                np.asarray(s["coordinates_mm"], dtype=np.float64).reshape(-1, 3),
            )
            for s in data["segments"]
        )
        links = tuple(
            Link(index[str(k["markers"][0])], index[str(k["markers"][1])],
                 float(k["range_mm"][0]), float(k["range_mm"][1]))
            for k in data.get("links", [])
        )  # fmt: skip
        seg_index = {seg.name: s for s, seg in enumerate(segments)}
        references = tuple(
            Reference(
                seg_index[str(r["segment"])],
                index[str(r["marker"])],
                np.asarray(r["direction"], dtype=np.float64).reshape(3),
                float(r["spread_deg"]),
                tuple(index[str(x)] for x in r.get("triple", [])),
                int(r.get("side", 0)),
            )
            for r in data.get("references", [])
        )
        tolerance = data.get("tolerance_mm")
        link_spread = data.get("link_spread_mm")
        learnt = (
            None if tolerance is None else float(tolerance),
            None if link_spread is None else float(link_spread),
        )
    except (OSError, ValueError, KeyError, TypeError, IndexError, AttributeError) as exc:
        raise ReconstructionError(f"{path}: not a marker model ({exc})") from None
    return labels, segments, links, learnt[0], learnt[1], references
