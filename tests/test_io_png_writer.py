"""8-bit PNGs are written by Pillow directly: the bytes imageio's Pillow plugin writes."""

from __future__ import annotations

import imageio.v3 as iio
import numpy as np
import pytest

from texsyn.io.encoders import encode_image


@pytest.mark.parametrize("shape", [(37, 29), (37, 29, 2), (37, 29, 3), (37, 29, 4)])
def test_png_bytes_are_imageios(tmp_path, shape):
    data = (np.random.default_rng(0).random(shape) * 255).astype(np.uint8)
    encode_image(tmp_path / "texsyn.png", data, ".png")
    iio.imwrite(tmp_path / "imageio.png", data, extension=".png")
    assert (tmp_path / "texsyn.png").read_bytes() == (tmp_path / "imageio.png").read_bytes()
    assert np.array_equal(iio.imread(tmp_path / "texsyn.png"), data)
