"""Image numerics: blob centroids of thresholded camera frames (passive markers).

``find_blobs`` is the marker detector of the video-centroid cameras (the host
side of the OAK driver); ``render_blobs`` draws the frames its tests measure.
"""

from spotlab.imaging.blobs import FLAG_EDGE, FLAG_SATURATED, FLAG_TOO_MANY, Blobs, find_blobs
from spotlab.imaging.errors import ImagingError
from spotlab.imaging.render import render_blobs

__all__ = [
    "FLAG_EDGE",
    "FLAG_SATURATED",
    "FLAG_TOO_MANY",
    "Blobs",
    "ImagingError",
    "find_blobs",
    "render_blobs",
]
