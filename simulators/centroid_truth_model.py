"""The walk from which ``spotlab sim centroid --model-out`` learns the simulated body's
marker model: a simulator output, made from the simulator's truth.

A real hub does not know its markers' names: they come from a subject's marker model
(labels, rigid clusters, distance links) that travels with the recording (``spotlab
record --model``), learnt in a lab from a static and a range-of-motion trial (``spotlab
model init`` / ``learn``, docs/identification.md). The simulator can hand out its body's
model directly: :func:`model_walk` gives the hub's markers over a few strides of the
walk, named by the truth's labels, and the ``sim`` command finds the clusters and links
in them (:meth:`~spotlab.reconstruction.identification.MarkerModel.infer`; simulators do
not reconstruct, so the inference stays with the command). Nothing but the simulator's
own outputs may use it: tests and benchmarks learn their models as a lab does.
"""

from __future__ import annotations

import numpy as np

from spotlab.simulators.centroid import F64, CentroidDevice
from spotlab.simulators.rigs import ring_rig

__all__ = ["MODEL_RATE_HZ", "MODEL_SECONDS", "model_walk"]

#: Walk sampled to learn the model (s): more than three strides of the 0.9 Hz gait.
MODEL_SECONDS = 4.0
#: Samples per second of that walk.
MODEL_RATE_HZ = 50.0


def model_walk(
    markers: int = 40, seed: int = 0, *, rate_hz: float = MODEL_RATE_HZ
) -> tuple[tuple[str, ...], F64]:
    """The true labels and positions of the first ``markers`` markers of the simulated hub
    over :data:`MODEL_SECONDS` of the walk.

    Parameters
    ----------
    markers : int
        As ``spotlab sim centroid --markers``: the walking body's 40, then static
        reference markers.
    seed : int
        As ``--seed`` (the subject, and the places of the static markers).
    rate_hz : float
        Samples per second of the walk.

    Returns
    -------
    labels : tuple of str, length M
        The truth file's ``labels``, in its order.
    positions : ndarray, shape (F, M, 3)
        The markers at times ``arange(F) / rate_hz`` s of the walk (mm),
        F = ``round(MODEL_SECONDS * rate_hz)``.
    """
    device = CentroidDevice(ring_rig(8), markers=markers, seed=seed)
    t = np.arange(round(MODEL_SECONDS * rate_hz)) / rate_hz
    return tuple(device.labels), device.positions(t)
