"""Reading and writing images: files in, float32 [0, 1] arrays out, atomic writes.

Read: PNG, JPEG, TIFF, BMP, GIF (first frame), WebP, PBM/PGM/PPM; 8 and 16 bit; grey, grey +
alpha, RGB, RGBA and palette images. Write: PNG, JPEG and TIFF (8 bit; 16 bit for PNG and
TIFF on request), always through a temporary file renamed into place, so that a failed or
interrupted write never leaves a partial file.
"""

from ..errors import ImageReadError
from .fitted import load_fitted, save_fitted
from .headers import ImageHeader, check_image_size, max_image_pixels, read_image_header
from .reading import READ_FORMATS, read_image
from .writing import (
    WRITE_FORMATS,
    OutputSet,
    atomic_write,
    check_output_path,
    sidecar_path,
    write_array,
    write_frames,
    write_image,
)

__all__ = [
    "ImageReadError",
    "READ_FORMATS",
    "WRITE_FORMATS",
    "read_image",
    "read_image_header",
    "ImageHeader",
    "check_image_size",
    "max_image_pixels",
    "write_image",
    "write_array",
    "write_frames",
    "check_output_path",
    "atomic_write",
    "OutputSet",
    "sidecar_path",
    "save_fitted",
    "load_fitted",
]
