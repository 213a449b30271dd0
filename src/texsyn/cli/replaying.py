"""The ``replay`` command: other images of a material carried along a saved source map.

``texsyn replay SOURCE_MAP.npy CHANNEL... -o OUT`` applies the map ``texsyn synth
--source-map x.npy`` wrote (an int32 ``(H, W, 2)`` array of exemplar ``(row, col)`` per output
pixel) to images of the exemplar's size (:func:`texsyn.ops.materials.replay`), with the bit
depths, value ranges and ICC profiles of ``texsyn synth`` (``docs/materials.md``).
"""

from __future__ import annotations

from pathlib import Path

import click
import numpy as np

from ..errors import InputError
from ..io import read_image_file
from ..io.arrays import load_npy
from ..ops.materials import LayerEncoding, is_normal_name, replay, unit_normals
from .common import done, output_set
from .materials import BIT_DEPTHS, output_folder, resolve_depth, stack_output_path, stored_image
from .options import overwrite_option, quiet_option

__all__ = ["replay_command"]


@click.command("replay")
@click.argument("source_map", metavar="SOURCE_MAP.npy")
@click.argument("channels", nargs=-1, required=True, metavar="CHANNEL...")
@click.option("-o", "--output", required=True, type=click.Path(), help="Output file (one CHANNEL) or folder.")
@click.option(
    "--normal",
    "normal_maps",
    multiple=True,
    metavar="CHANNEL",
    help="A CHANNEL that is a normal map, renormalised to unit length (repeatable; names with 'normal' are taken anyway).",
)
@click.option(
    "--bit-depth",
    type=click.Choice(BIT_DEPTHS),
    default="auto",
    show_default=True,
    help="Output samples; auto keeps each channel's.",
)
@overwrite_option()
@quiet_option
def replay_command(source_map, channels, output, normal_maps, bit_depth, overwrite, quiet):
    """Carry CHANNEL images along SOURCE_MAP.npy, a map `texsyn synth --source-map` wrote.

    SOURCE_MAP.npy is an int32 (H, W, 2) array of exemplar (row, col) per output pixel; every
    CHANNEL must have the exemplar's size. One CHANNEL: OUTPUT is a file (or a folder);
    several: OUTPUT is a folder receiving one file per CHANNEL, same names.
    """
    unknown = [n for n in normal_maps if n not in channels]
    if unknown:
        raise click.UsageError(f"--normal {unknown[0]} is not one of the CHANNEL arguments")
    outputs = output_set(overwrite)
    outputs.add_input(source_map, "source map")
    for path in channels:
        outputs.add_input(path, "channel")
    folder = Path(output)
    as_folder = len(channels) > 1 or folder.is_dir() or not folder.suffix
    src = load_npy(source_map, "a source map")
    with output_folder(folder if as_folder else None):
        layers = []
        for path in channels:
            found = read_image_file(path)
            if layers and found.pixels.shape[:2] != layers[0][0].pixels.shape[:2]:
                first = layers[0][0].pixels.shape
                raise InputError(
                    f"'{path}' is {found.pixels.shape[1]}x{found.pixels.shape[0]} and '{channels[0]}' "
                    f"{first[1]}x{first[0]}; every CHANNEL must have the exemplar's size"
                )
            target = stack_output_path(folder, path) if as_folder else folder
            normal = path in normal_maps or is_normal_name(Path(path).name)
            if normal and (found.pixels.ndim != 3 or found.pixels.shape[2] != 3):
                raise InputError(
                    f"normal map '{path}' must have three channels (x, y, z), got {found.pixels.shape}"
                )
            depth = resolve_depth(bit_depth, found.bit_depth, target, "output")
            layers.append((found, outputs.claim(target, bit_depth=depth), depth, normal))
        with outputs:
            for found, target, depth, normal in layers:
                out = replay(src, found.pixels).astype(np.float64)
                encoding = LayerEncoding.of(found.pixels)
                if normal:
                    out = unit_normals(out, encoded=encoding.is_identity)
                image = stored_image(out, encoding, depth)
                outputs.write_image(target, image, bit_depth=depth, icc_profile=found.icc_profile)
    h, w = src.shape[:2]
    done(quiet, None, False, f"wrote {', '.join(str(t) for _, t, _, _ in layers)} ({w}x{h})")
