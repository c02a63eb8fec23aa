"""Image numerics: blob centroids of thresholded camera frames (passive markers)."""
