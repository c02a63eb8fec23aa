"""render_blobs: brightness, symmetry, clipping to the image, noise and errors."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose

from spotlab.imaging import ImagingError, render_blobs


def test_disc_flux_is_its_blurred_area_times_brightness() -> None:
    img = render_blobs((40, 40), [[19.3, 20.6]], 8.0, peak=100.0, background=0.0, dtype=np.uint16)
    # The blurred edge 0.5 erfc((r - R) / (sqrt(2) s)) integrates to pi (R^2 + s^2).
    assert_allclose(img.sum(), np.pi * (16 + 0.5**2) * 100, rtol=2e-3)
    assert img.max() == 100


def test_blob_centred_on_a_pixel_is_symmetric() -> None:
    img = render_blobs((21, 21), [[10.0, 10.0]], 6.0, background=0.0, dtype=np.uint16)
    assert np.array_equal(img, img[::-1, :]) and np.array_equal(img, img.T)


def test_blob_at_the_corner_is_cut_and_nan_rows_are_skipped() -> None:
    img = render_blobs((30, 20), [[0.0, 0.0], [np.nan, 5.0]], 8.0, background=0.0)
    assert img[0, 0] > 0 and img[15:, 15:].sum() == 0


def test_saturation_clips_at_the_dtype_maximum() -> None:
    img = render_blobs((20, 20), [[10.0, 10.0]], 6.0, peak=400.0)
    assert img.max() == 255 and img.dtype == np.uint8


def test_noise_has_the_requested_spread() -> None:
    rng = np.random.default_rng(0)
    img = render_blobs((200, 200), np.zeros((0, 2)), 5.0, background=100.0, noise=3.0, rng=rng)
    assert_allclose(img.std(), 3.0, rtol=0.05)


@pytest.mark.parametrize(
    "kwargs",
    [{"size": (0, 10)}, {"diameters": -1.0}, {"profile": "square"}, {"oversample": 0}],
)
def test_bad_options_raise(kwargs: dict) -> None:
    args = {"size": (10, 10), "centers": [[5.0, 5.0]], "diameters": 3.0, **kwargs}
    with pytest.raises(ImagingError):
        render_blobs(**args)
