"""Marker identification for passive markers: blobs of several cameras -> labelled points.

Correspondence between cameras (:mod:`.correspondence`), tracking in time
(:mod:`.tracking`), labels from a marker model of rigid clusters and distance links
(:mod:`.model`, :mod:`.labelling`, :mod:`.link_labels`), all driven frame by frame by
:class:`Identifier`.
Methods and measured figures: ``docs/identification.md``.
"""

from spotlab.reconstruction.identification.blobs import BlobFrame
from spotlab.reconstruction.identification.correspondence import Correspondence, match_blobs
from spotlab.reconstruction.identification.fit import ModelFit, model_fit
from spotlab.reconstruction.identification.geometry import RigGeometry
from spotlab.reconstruction.identification.identified_frame import (
    FLOODED,
    NO_BLOBS,
    UNUSABLE,
    IdentifiedFrame,
)
from spotlab.reconstruction.identification.identifier import Identifier
from spotlab.reconstruction.identification.model import Link, MarkerModel, Segment

__all__ = [
    "FLOODED",
    "NO_BLOBS",
    "UNUSABLE",
    "BlobFrame",
    "Correspondence",
    "IdentifiedFrame",
    "Identifier",
    "Link",
    "MarkerModel",
    "ModelFit",
    "RigGeometry",
    "Segment",
    "match_blobs",
    "model_fit",
]
