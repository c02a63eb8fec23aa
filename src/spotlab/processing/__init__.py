"""Processing: recording -> observations -> identification or triangulation ->
trajectories -> files, one entry point per step (docs/processing.md).

The command line (``spotlab export``, ``reconstruct``, ``replay``, ``calibrate``) parses
its options and prints; the work is done here, and a script, a bench or a HIL test calls
the same functions. Nothing here prints or reads ``sys.argv``: an input that cannot be
used raises :class:`InputError` (or an error of :mod:`spotlab.core.errors`), progress
goes to a :class:`ProgressSink` the caller gives, notes for the user come back in the
results.

The steps:

1. open a recording: :func:`open_recording` (every stream decoded and on session time),
   :func:`recording_timebase`, :func:`decode_streams`;
2. observations: :func:`load_observations` (npz, CSV or a one-device SELSPOT recording),
   :func:`synchronise_observations` (the ``image2d`` streams of an opened recording at
   common session instants), :func:`read_blob_recording` (video-centroid blobs);
3. identify or triangulate: :func:`reconstruct` (triangulation),
   :func:`identify_recording` (blobs labelled by a marker model);
4. trajectories of a file in one call: :func:`reconstruct_recording` (what
   ``spotlab export REC.spj`` does), :func:`reconstruct_file`, :func:`export_synchronised`;
5. export: :func:`write_trial` (C3D or TRC), :func:`write_timestamps` (CSV).

Names are loaded on first use: importing :mod:`spotlab.processing.errors` (which the
command line does at start-up) stays free of numpy.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from spotlab.processing.blob_trajectories import (
        BlobRecording,
        BlobTrajectories,
        identify_recording,
        is_blob_recording,
        load_model,
        read_blob_recording,
    )
    from spotlab.processing.decoding import decoder_for, input_suffix
    from spotlab.processing.errors import InputError
    from spotlab.processing.marker_observations import (
        OBSERVATION_SUFFIXES,
        MarkerObservations,
        load_observations,
    )
    from spotlab.processing.paths import check_output_paths
    from spotlab.processing.progress import ProgressFactory, ProgressSink
    from spotlab.processing.session_times import (
        DecodedStreams,
        calibration_for,
        decode_streams,
        recording_timebase,
        write_timestamps,
    )
    from spotlab.processing.synchronised_export import (
        ImageStream,
        OpenedRecording,
        SynchronisedExport,
        SynchronisedObservations,
        export_synchronised,
        open_recording,
        reconstruct_recording,
        synchronise_observations,
    )
    from spotlab.processing.trajectories import (
        Reconstruction,
        check_outputs,
        load_rig,
        reconstruct,
        reconstruct_file,
        write_trial,
    )

_MODULES: dict[str, tuple[str, ...]] = {
    "spotlab.processing.blob_trajectories": (
        "BlobRecording",
        "BlobTrajectories",
        "identify_recording",
        "is_blob_recording",
        "load_model",
        "read_blob_recording",
    ),
    "spotlab.processing.decoding": ("decoder_for", "input_suffix"),
    "spotlab.processing.errors": ("InputError",),
    "spotlab.processing.marker_observations": (
        "OBSERVATION_SUFFIXES",
        "MarkerObservations",
        "load_observations",
    ),
    "spotlab.processing.paths": ("check_output_paths",),
    "spotlab.processing.progress": ("ProgressFactory", "ProgressSink"),
    "spotlab.processing.session_times": (
        "DecodedStreams",
        "calibration_for",
        "decode_streams",
        "recording_timebase",
        "write_timestamps",
    ),
    "spotlab.processing.synchronised_export": (
        "ImageStream",
        "OpenedRecording",
        "SynchronisedExport",
        "SynchronisedObservations",
        "export_synchronised",
        "open_recording",
        "reconstruct_recording",
        "synchronise_observations",
    ),
    "spotlab.processing.trajectories": (
        "Reconstruction",
        "check_outputs",
        "load_rig",
        "reconstruct",
        "reconstruct_file",
        "write_trial",
    ),
}
_LAZY = {name: module for module, names in _MODULES.items() for name in names}


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'spotlab.processing' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


__all__ = [
    "OBSERVATION_SUFFIXES",
    "BlobRecording",
    "BlobTrajectories",
    "DecodedStreams",
    "ImageStream",
    "InputError",
    "MarkerObservations",
    "OpenedRecording",
    "ProgressFactory",
    "ProgressSink",
    "Reconstruction",
    "SynchronisedExport",
    "SynchronisedObservations",
    "calibration_for",
    "check_output_paths",
    "check_outputs",
    "decode_streams",
    "decoder_for",
    "export_synchronised",
    "identify_recording",
    "input_suffix",
    "is_blob_recording",
    "load_model",
    "load_observations",
    "load_rig",
    "open_recording",
    "read_blob_recording",
    "reconstruct",
    "reconstruct_file",
    "reconstruct_recording",
    "recording_timebase",
    "synchronise_observations",
    "write_timestamps",
    "write_trial",
]
