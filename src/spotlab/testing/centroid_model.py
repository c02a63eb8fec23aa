"""The marker model of a simulated CEN hub's markers (``spotlab sim centroid --model-out``), learnt
from the simulator's truth: a shortcut for tests, kept in spotlab.testing with the scoring.

A real hub does not know its markers' names: they come from a subject template, a
:class:`~spotlab.reconstruction.identification.MarkerModel` (names, rigid clusters,
distance links), that travels with the recording (``spotlab record --model``). For the
simulator the template is learnt from the body's own motion: the hub's markers over a
few strides of the walk, the labels of its truth file, clusters and links found by
:meth:`MarkerModel.infer` (markers whose distances stay constant, and for markers that
are not on a rigid cluster of three — skin over a joint — the ranges of their distances).
"""

from __future__ import annotations

import os

import numpy as np

from spotlab.reconstruction.identification import MarkerModel
from spotlab.simulators.centroid import CentroidDevice
from spotlab.simulators.rigs import ring_rig

__all__ = ["MODEL_SECONDS", "body_marker_model", "write_body_model"]

#: Walk sampled to learn the model (s): more than three strides of the 0.9 Hz gait.
MODEL_SECONDS = 4.0


def body_marker_model(markers: int = 40, seed: int = 0, *, rate_hz: float = 50.0) -> MarkerModel:
    """The marker model of the first ``markers`` markers of the simulated hub.

    Parameters
    ----------
    markers : int
        As ``spotlab sim centroid --markers``: the walking body's 40, then static
        reference markers.
    seed : int
        As ``--seed`` (places the static markers).
    rate_hz : float
        Samples per second of the walk the model is learnt from.

    Returns
    -------
    MarkerModel
        Labels in the order of the simulator's truth ``labels``.

    Raises
    ------
    ReconstructionError
        When some marker can be identified neither by a cluster nor by its links (for
        example one or two static markers alone).
    """
    device = CentroidDevice(ring_rig(8), markers=markers, seed=seed)
    t = np.arange(round(MODEL_SECONDS * rate_hz)) / rate_hz
    # infer's defaults: the links' spread is chosen from the walk, and a marker on no
    # cluster is linked to its 3 least varying partners too (a subject's toe marker swings
    # 60-100 mm against every other marker; a fixed 60 or 80 mm left some without links).
    return MarkerModel.infer(device.labels, device.positions(t))


def write_body_model(path: str | os.PathLike[str], markers: int = 40, seed: int = 0) -> None:
    """Write :func:`body_marker_model` as JSON (:meth:`MarkerModel.save`)."""
    body_marker_model(markers, seed).save(path)
