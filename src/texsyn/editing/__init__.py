"""Editing with textures: fill a hole, transfer a texture onto an image, guide where it goes.

Layer 8 (``docs/architecture.md``): the front of three editing tasks that the copy-based
methods of layer 7 run with their own drivers and searches (``docs/editing.md``):

- :func:`fill`: inpainting, the constrained synthesis of Efros and Leung (1999, section 2)
  and its block form with image quilting;
- :func:`transfer`: Efros and Freeman's texture transfer (2001, section 3);
- :func:`synthesize_guided`: guided synthesis, a guide map of the exemplar and one of the
  output saying which material goes where.

Each returns a :class:`~texsyn.methods.SynthesisResult` (image and source map).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .._lazy import lazy_exports

if TYPE_CHECKING:  # the names for type checkers; at run time ``__getattr__`` loads them
    from .guided import GUIDED_METHODS, synthesize_guided
    from .inpainting import FILL_METHODS, fill, hole_mask
    from .texture_transfer import TRANSFER_METHODS, correspondence_map, transfer

__all__ = [
    "FILL_METHODS",
    "GUIDED_METHODS",
    "TRANSFER_METHODS",
    "correspondence_map",
    "fill",
    "hole_mask",
    "synthesize_guided",
    "transfer",
]

__getattr__, __dir__ = lazy_exports(
    __name__,
    {
        "FILL_METHODS": "inpainting",
        "fill": "inpainting",
        "hole_mask": "inpainting",
        "GUIDED_METHODS": "guided",
        "synthesize_guided": "guided",
        "TRANSFER_METHODS": "texture_transfer",
        "correspondence_map": "texture_transfer",
        "transfer": "texture_transfer",
    },
)
