"""The editing commands: ``fill`` (inpainting) and ``transfer`` (texture transfer); ``docs/editing.md``.

Like ``synth`` (:mod:`~texsyn.cli.synthesis`), each claims its outputs before any work and
writes them all or none, with a JSON sidecar; the work is :mod:`texsyn.editing`'s.
"""

from __future__ import annotations

import click
import numpy as np

from ..editing import FILL_METHODS, TRANSFER_METHODS, fill, hole_mask, transfer
from ..errors import InputError
from ..io import read_image, sidecar_path
from ..io.writing import JSON_FORMATS
from ..methods import make_method
from ..ops import position_colors
from .common import (
    check_memory_before_reading,
    claim_extra,
    done,
    draw_seed,
    input_path,
    load_exemplar,
    output_set,
    planned_shape,
    sidecar_json,
    stage_extra,
)
from .options import (
    Number,
    bit_depth_option,
    output_option,
    overwrite_option,
    param_option,
    parse_params,
    quiet_option,
    seed_option,
)
from .progress import ProgressBar

__all__ = ["fill_command", "transfer_command"]

_SOURCE_MAP_HELP = (
    "Also write where each pixel came from (.npy array, or a .png/.tif position-colour picture)."
)


def _position_picture(shape: tuple[int, ...]):
    """Source map -> picture; the pixels with no source (-1) are black."""

    def picture(source: np.ndarray) -> np.ndarray:
        colours = position_colors(source, (shape[0], shape[1]))
        colours[np.any(source < 0, axis=-1)] = 0.0
        return colours

    return picture


@click.command("fill")
@click.argument("image")
@click.option(
    "--mask",
    type=click.Path(dir_okay=False),
    help="Black and white image of IMAGE's size: white marks the pixels to fill [default: the transparent pixels of IMAGE].",
)
@output_option("Output image (.png, .jpg, .tif).")
@click.option(
    "-m",
    "--method",
    default="efros_leung",
    show_default=True,
    help=f"Fill method: {', '.join(FILL_METHODS)} (docs/editing.md).",
)
@click.option(
    "-e",
    "--exemplar",
    help="Texture to copy from (an image file or builtin:NAME) [default: the known part of IMAGE].",
)
@click.option(
    "--context",
    type=click.IntRange(1, 100_000),
    metavar="N",
    help="Without --exemplar, copy only from within N pixels of the hole (a large photo) [default: the whole image].",
)
@seed_option("output")
@param_option("Method parameter (repeatable).")
@click.option("--source-map", type=click.Path(dir_okay=False), help=_SOURCE_MAP_HELP)
@bit_depth_option
@overwrite_option()
@quiet_option
def fill_command(
    image, mask, output, method, exemplar, context, seed, params, source_map, bit_depth, overwrite, quiet
):
    """Fill a hole of IMAGE with texture; the other pixels are kept exactly.

    The hole is the white part of MASK (or the transparent part of IMAGE). It is filled
    from the rest of IMAGE, or from EXEMPLAR: efros_leung grows it pixel by pixel from its
    border inwards (onion peel, the pixels with the most known neighbours first);
    quilting covers it with blocks matched on the known pixels. Also writes OUTPUT.json.
    """
    if method not in FILL_METHODS:
        raise InputError(
            f"method {method!r} cannot fill holes; methods that can: {', '.join(FILL_METHODS)} (docs/editing.md)"
        )
    depth = int(bit_depth)
    parameters = parse_params(method, params)
    synthesizer = make_method(method, **parameters)
    outputs = output_set(overwrite)
    outputs.add_input(image, "IMAGE")
    outputs.add_input(mask, "mask")
    outputs.add_input(input_path(exemplar), "exemplar")
    out_path = outputs.claim(output, bit_depth=depth)
    map_path = claim_extra(outputs, source_map, "source map")
    side_path = outputs.claim(sidecar_path(out_path), formats=JSON_FORMATS, what="sidecar")

    shape = planned_shape(image)
    if context is None or exemplar is not None:  # with a context, fit checks the part it gets
        check_memory_before_reading(synthesizer, exemplar or image, shape[:2] if shape else None)
    pixels = read_image(image, keep_alpha=mask is None)
    if mask is None:
        if pixels.ndim != 3 or pixels.shape[2] not in (2, 4):
            raise InputError(f"'{image}' has no alpha channel; give --mask (white: the pixels to fill)")
        hole = pixels[..., -1] < 0.5
        pixels = pixels[..., :-1]
        if pixels.shape[2] == 1:
            pixels = pixels[..., 0]
    else:
        hole = hole_mask(read_image(mask), pixels.shape[:2], name=f"mask '{mask}'")
    texture, label = (None, "the image") if exemplar is None else load_exemplar(exemplar)
    seed, drawn = draw_seed(seed)
    bar = ProgressBar(f"fill {method}", enabled=not quiet)
    try:
        result = fill(
            pixels,
            hole,
            method=method,
            exemplar=texture,
            context=context,
            rng=seed,
            callback=bar,
            **parameters,
        )
    finally:
        bar.close()
    h, w = result.image.shape[:2]
    sidecar = sidecar_json(
        "fill",
        outputs={"image": out_path, "source_map": map_path, "sidecar": side_path},
        inputs={"image": image, "mask": mask, "exemplar": exemplar},
        method=method,
        params=synthesizer.get_params(),
        seed=seed,
        options={"bit_depth": depth, "context": context, "hole_pixels": int(hole.sum())},
    )
    origin = pixels.shape if texture is None else texture.shape
    with outputs:
        outputs.write_image(out_path, result.image, bit_depth=depth)
        stage_extra(outputs, map_path, result.source_map, _position_picture(origin))
        outputs.write_text(side_path, sidecar)
    done(
        quiet,
        seed,
        drawn,
        f"wrote {out_path} ({w}x{h}, {int(hole.sum())} pixels filled by {method} from {label}) and {side_path}",
    )


@click.command("transfer")
@click.argument("texture")
@click.argument("target")
@output_option("Output image (.png, .jpg, .tif); it has TARGET's size and TEXTURE's channels.")
@click.option(
    "-m",
    "--method",
    default="quilting",
    show_default=True,
    help=f"Transfer method: {', '.join(TRANSFER_METHODS)} (efros_leung: one pass, --iterations 1).",
)
@click.option(
    "--alpha",
    type=Number(0.0, 1.0),
    default=0.1,
    show_default=True,
    help="Weight of the agreement with the blocks already placed, against the agreement with TARGET, in the first iteration (later ones raise it to 0.9).",
)
@click.option(
    "--iterations",
    type=click.IntRange(1, 10),
    help="Passes, the block shrinking by a third after each [default: 3; efros_leung: 1, its only choice].",
)
@click.option(
    "--block",
    type=click.IntRange(3, 1024),
    help="Side of the first iteration's blocks (parameter 'patch_size' of quilting) [default: 32].",
)
@click.option(
    "--blur",
    type=Number(0.0, 100.0),
    default=1.0,
    show_default=True,
    help="Gaussian blur (pixels) of the luminance maps that are matched.",
)
@click.option(
    "--texture-map",
    type=click.Path(dir_okay=False),
    help="Correspondence map of TEXTURE (an image of its size) instead of its blurred luminance; needs --target-map.",
)
@click.option(
    "--target-map",
    type=click.Path(dir_okay=False),
    help="Correspondence map of the output (an image of TARGET's size) instead of TARGET's blurred luminance.",
)
@seed_option("output")
@param_option("Parameter of the quilting method (repeatable).")
@click.option("--source-map", type=click.Path(dir_okay=False), help=_SOURCE_MAP_HELP)
@bit_depth_option
@overwrite_option()
@quiet_option
def transfer_command(
    texture,
    target,
    output,
    method,
    alpha,
    iterations,
    block,
    blur,
    texture_map,
    target_map,
    seed,
    params,
    source_map,
    bit_depth,
    overwrite,
    quiet,
):
    """Render TARGET with the texture TEXTURE (image quilting's texture transfer).

    Blocks of TEXTURE are quilted so that the output's blurred luminance follows TARGET's
    (Efros and Freeman 2001, section 3). Also writes OUTPUT.json.
    """
    if method not in TRANSFER_METHODS:
        raise InputError(
            f"method {method!r} does not transfer textures; methods that do: {', '.join(TRANSFER_METHODS)}"
        )
    depth = int(bit_depth)
    parameters = parse_params(method, params)
    if block is not None:
        if method != "quilting":
            raise click.UsageError("--block is quilting's block size; efros_leung takes -p window_size=...")
        if "patch_size" in parameters:
            raise click.UsageError("give --block or -p patch_size=..., not both")
        parameters["patch_size"] = block
    if (texture_map is None) != (target_map is None):
        raise click.UsageError("give both --texture-map and --target-map, or neither")
    synthesizer = make_method(method, **parameters)
    outputs = output_set(overwrite)
    for path, what in (
        (texture, "TEXTURE"),
        (target, "TARGET"),
        (texture_map, "texture map"),
        (target_map, "target map"),
    ):
        outputs.add_input(input_path(path), what)
    out_path = outputs.claim(output, bit_depth=depth)
    map_path = claim_extra(outputs, source_map, "source map")
    side_path = outputs.claim(sidecar_path(out_path), formats=JSON_FORMATS, what="sidecar")

    aim_shape = planned_shape(target)
    check_memory_before_reading(synthesizer, texture, aim_shape[:2] if aim_shape else None)
    tex, label = load_exemplar(texture)
    aim, _ = load_exemplar(target)
    maps = {}
    if texture_map is not None:
        maps = {"texture_map": read_image(texture_map), "target_map": read_image(target_map)}
    seed, drawn = draw_seed(seed)
    bar = ProgressBar("transfer", enabled=not quiet)
    try:
        result = transfer(
            tex,
            aim,
            alpha=alpha,
            iterations=iterations,
            blur=blur,
            rng=seed,
            callback=bar,
            **maps,
            **parameters,
        )
    finally:
        bar.close()
    h, w = result.image.shape[:2]
    sidecar = sidecar_json(
        "transfer",
        outputs={"image": out_path, "source_map": map_path, "sidecar": side_path},
        inputs={"texture": texture, "target": target, "texture_map": texture_map, "target_map": target_map},
        method=method,
        params=synthesizer.get_params(),
        seed=seed,
        options={"alpha": alpha, "iterations": iterations, "blur": blur, "bit_depth": depth},
    )
    with outputs:
        outputs.write_image(out_path, result.image, bit_depth=depth)
        stage_extra(outputs, map_path, result.source_map, _position_picture(tex.shape))
        outputs.write_text(side_path, sidecar)
    done(quiet, seed, drawn, f"wrote {out_path} ({w}x{h}, {label} onto {target}) and {side_path}")
