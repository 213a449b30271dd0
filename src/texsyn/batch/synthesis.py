"""One output, made exactly as ``texsyn synth`` makes it (``docs/batch.md``, "Same bytes").

``texsyn synth`` and every batch item read the exemplar argument the same way
(:func:`texsyn.data.load_exemplar`: a file, or ``builtin:NAME``), fit the method, and write the texture
with :func:`write_texture`: a method that synthesises in raster order streams its bands of
rows to the file (:func:`stream_bands`, ``docs/performance.md``), any other is sampled whole
and written with :meth:`~texsyn.io.OutputSet.write_image`. The two paths encode a PNG
differently, so sharing them is what makes a batch item byte-identical to the ``synth``
command with the same seed.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..data import BUILTIN_PREFIX, read_exemplar
from ..errors import InputError
from ..io import OutputSet
from ..io.reading import ImageFile
from ..methods import SynthesisResult, TextureSynthesizer
from ..ops import position_colors

__all__ = ["input_path", "read_batch_exemplar", "stream_bands", "write_texture"]


def input_path(name: str | None) -> str | None:
    """The file an exemplar/INPUT argument names (``None`` for the built-in textures)."""
    if name is None or name.startswith(BUILTIN_PREFIX):
        return None
    return name


def read_batch_exemplar(path: str | Path, name: str | None = None) -> ImageFile:
    """An exemplar file as ``texsyn synth`` reads it (samples, bit depth, ICC profile), for a
    batch item, which writes a PNG at the exemplar's bit depth with its profile as ``synth``
    does by default (``--bit-depth auto``, ``docs/materials.md``).

    Raises
    ------
    InputError
        An exemplar with alpha or floating-point samples: ``synth`` makes a material of the
        one and cannot write the other to PNG; batch items are PNG images of colour or grey.
    """
    found, label = read_exemplar(str(path))
    shown = name or label
    if found.pixels.ndim == 3 and found.pixels.shape[2] in (2, 4):
        raise InputError(
            f"'{shown}' has an alpha channel; batch items are colour or grey PNGs: use texsyn synth, "
            "which carries alpha (docs/materials.md)"
        )
    if found.bit_depth == 32:
        raise InputError(
            f"'{shown}' holds floating-point samples, which a PNG cannot; use texsyn synth with a "
            ".tif, .npy or .exr output (docs/materials.md)"
        )
    return found


def write_texture(
    outputs: OutputSet,
    synthesizer: TextureSynthesizer,
    shape: tuple[int, int],
    seed: int,
    image_path: Path,
    exemplar_shape: tuple[int, ...],
    *,
    bit_depth: int = 8,
    icc_profile: bytes | None = None,
    callback=None,
) -> SynthesisResult | None:
    """Sample a fitted ``synthesizer`` and write the texture to ``image_path``, as ``synth`` does.

    ``image_path`` was claimed in ``outputs``; the set is committed here. A method that
    streams its rows (:attr:`~texsyn.methods.TextureSynthesizer.streams_rows`) writes them
    band by band and returns ``None``; any other returns its
    :class:`~texsyn.methods.SynthesisResult` after writing ``result.image``.
    """
    if synthesizer.streams_rows:
        with outputs:
            stream_bands(
                outputs,
                synthesizer,
                shape,
                seed,
                callback,
                exemplar_shape,
                image_path,
                None,
                bit_depth,
                icc_profile=icc_profile,
            )
        return None
    result = synthesizer.sample_with_map(shape, rng=seed, callback=callback)
    with outputs:
        outputs.write_image(image_path, result.image, bit_depth=bit_depth, icc_profile=icc_profile)
    return result


def stream_bands(
    outputs,
    synthesizer,
    shape,
    seed,
    bar,
    exemplar_shape,
    out_path,
    map_path,
    depth,
    *,
    store=None,
    icc_profile: bytes | None = None,
) -> None:
    """Write the bands of :meth:`~texsyn.methods.TextureSynthesizer.sample_rows` to the image
    and source map files as they come: the float output is never held whole. ``store``
    turns a band into the values the file keeps (``texsyn synth``'s value range and linear
    light, ``docs/materials.md``); ``icc_profile`` is embedded in the image."""
    channels = () if len(exemplar_shape) == 2 else (exemplar_shape[2],)
    image_rows = outputs.open_rows(
        out_path, tuple(shape) + channels, bit_depth=depth, icc_profile=icc_profile
    )
    map_rows = None
    npy = False
    if map_path is not None:
        npy = map_path.suffix.lower() == ".npy"
        map_rows = outputs.open_rows(map_path, tuple(shape) + ((2,) if npy else (3,)), dtype=np.int32)
    for band in synthesizer.sample_rows(shape, rng=seed, callback=bar):
        image_rows.write(band.image if store is None else store(band.image))
        if map_rows is not None:
            source = band.source_map
            map_rows.write(source if npy else position_colors(source, exemplar_shape[:2]))
    image_rows.close()
    if map_rows is not None:
        map_rows.close()
