"""Video-centroid hub family (CEN, docs/protocols/centroid.md): passive-marker cameras
that send blob centroids, on the MCS-1 transport.

* :class:`CentroidDriver` — the driver;
* :class:`CentroidDecoder` — bytes to ``blobs2d`` frame blocks (layout in ``protocol``);
* :func:`blobs_from_blocks` / :class:`BlobFrames` — blocks to a ragged blob table.
"""

from spotlab.drivers.centroid.blobs import BlobFrames, blobs_from_blocks
from spotlab.drivers.centroid.config import CentroidConfig
from spotlab.drivers.centroid.driver import CentroidDriver
from spotlab.drivers.centroid.protocol import (
    BLOB_EDGE,
    BLOB_MERGED,
    BLOB_SATURATED,
    CAM_OFFLINE,
    CAM_OVERFLOW,
    CentroidDecoder,
    decoder_from_metadata,
)

__all__ = [
    "BLOB_EDGE",
    "BLOB_MERGED",
    "BLOB_SATURATED",
    "CAM_OFFLINE",
    "CAM_OVERFLOW",
    "BlobFrames",
    "CentroidConfig",
    "CentroidDecoder",
    "CentroidDriver",
    "blobs_from_blocks",
    "decoder_from_metadata",
]
