"""Reading and writing images: files in, float32 [0, 1] arrays out, atomic writes.

Read: PNG, JPEG, TIFF, BMP, GIF (first frame), WebP, PBM/PGM/PPM, ``.npy`` and OpenEXR; 8
and 16 bit and floating point; grey, grey + alpha, RGB, RGBA and palette images. Write: PNG,
JPEG and TIFF (8 bit; 16 bit for PNG and TIFF on request; 32-bit float TIFF), ``.npy`` and
OpenEXR (float), with an ICC profile on request, always through a temporary file renamed
into place, so that a failed or interrupted write never leaves a partial file.

``save_fitted`` and ``load_fitted`` (texsyn 0.1) still resolve, with a
:class:`DeprecationWarning`, through the module ``__getattr__`` below: fitted models are
saved with :func:`texsyn.save` and loaded with :func:`texsyn.load` (``docs/persistence.md``).
"""

import importlib
import sys
import warnings

from ..errors import ImageReadError
from .headers import ImageHeader, check_image_size, max_image_pixels, read_image_header
from .reading import READ_FORMATS, ImageFile, read_image, read_image_file
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
    "read_image_file",
    "ImageFile",
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
]

#: deprecated names and what replaces them
_DEPRECATED = {
    "save_fitted": "texsyn.save(model, path, overwrite=True)",
    "load_fitted": "texsyn.load(path)",
}


def __getattr__(name: str):
    """Deprecated names of :data:`_DEPRECATED`: resolved lazily, with a warning."""
    if name in _DEPRECATED or name == "fitted":
        module = sys.modules.get(f"{__name__}.fitted")
        if module is None:
            with warnings.catch_warnings():  # the alias module's own warning would repeat ours
                warnings.simplefilter("ignore", DeprecationWarning)
                module = importlib.import_module(".fitted", __name__)
        use = _DEPRECATED.get(name, "texsyn.save and texsyn.load")
        warnings.warn(f"texsyn.io.{name} is deprecated; use {use}", DeprecationWarning, stacklevel=2)
        return module if name == "fitted" else getattr(module, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
