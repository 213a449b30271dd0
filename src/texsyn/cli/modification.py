"""The ``modify`` command: a texture rebuilt toward an exemplar (Peyré 2007, section 5.2).

Outputs are claimed before any work and written all or none, with a JSON sidecar, like
``synth`` (:mod:`~texsyn.cli.synthesis`).
"""

from __future__ import annotations

import click
import numpy as np

from ..io import sidecar_path
from ..io.writing import JSON_FORMATS
from ..methods import make_method
from ..ops import position_colors
from .common import (
    check_memory_before_reading,
    claim_extra,
    done,
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
)
from .progress import ProgressBar

__all__ = ["modify"]


@click.command()
@click.argument("input_image", metavar="INPUT")
@click.option(
    "-e",
    "--exemplar",
    required=True,
    help="Exemplar whose patches rebuild INPUT (an image file, or builtin:brick|grass|gravel).",
)
@click.option(
    "-r",
    "--ratio",
    type=Number(0.0, 1.0),
    default=0.5,
    show_default=True,
    help="Share of INPUT whose details are removed (or, with --thresholding coefficient, the threshold as a fraction of the largest detail): 0 rebuilds INPUT, 1 is a pure synthesis.",
)
@output_option("Output image (.png, .jpg, .tif).")
@click.option(
    "--magnitudes",
    type=click.Path(dir_okay=False),
    help="Also write the kept detail magnitudes packed like a wavelet transform: a .npy array, or a .png/.tif picture (square root of magnitude / largest).",
)
@click.option(
    "--source-map",
    type=click.Path(dir_okay=False),
    help="Also write the exemplar position of every output pixel (.npy array, or a .png/.tif position-colour picture).",
)
@click.option("--no-equalize", is_flag=True, help="Do not match the exemplar's colours to INPUT first.")
@click.option(
    "--boundary",
    type=click.Choice(["symmetric", "periodic"]),
    default="symmetric",
    show_default=True,
    help="Border rule of the transform (periodic for an INPUT that tiles).",
)
@click.option("--per-level", is_flag=True, help="Threshold every level against its own largest detail.")
@click.option(
    "--thresholding",
    type=click.Choice(["local", "coefficient"]),
    default="local",
    show_default=True,
    help="Remove details by regions of low detail energy, or one by one as in the paper (section 5.2).",
)
@param_option("Parameter of the patch_wavelet method (repeatable).")
@bit_depth_option
@overwrite_option()
@quiet_option
def modify(
    input_image,
    exemplar,
    ratio,
    output,
    magnitudes,
    source_map,
    no_equalize,
    boundary,
    per_level,
    thresholding,
    params,
    bit_depth,
    overwrite,
    quiet,
):
    """Modify the texture INPUT (an image file or builtin:NAME) toward EXEMPLAR (Peyré 2007).

    INPUT is expressed with the exemplar's patches and decomposed; its wavelet details are
    removed on the share RATIO of INPUT where they carry the least energy (with
    --thresholding coefficient: those below RATIO times the largest) before rebuilding.
    Deterministic (no seed). Also writes OUTPUT.json.
    """
    depth = int(bit_depth)
    parameters = parse_params("patch_wavelet", params)
    method = make_method("patch_wavelet", **parameters)
    outputs = output_set(overwrite)
    outputs.add_input(input_path(input_image), "INPUT")
    outputs.add_input(input_path(exemplar), "exemplar")
    out_path = outputs.claim(output, bit_depth=depth)
    mag_path = claim_extra(outputs, magnitudes, "magnitudes output")
    map_path = claim_extra(outputs, source_map, "source map")
    side_path = outputs.claim(sidecar_path(out_path), formats=JSON_FORMATS, what="sidecar")

    check_memory_before_reading(method, exemplar, planned_shape(input_image))
    texture, _ = load_exemplar(input_image)
    image, label = load_exemplar(exemplar)
    bar = ProgressBar("modify", enabled=not quiet)
    try:
        method.fit(image)
        result = method.modify(
            texture,
            ratio,
            equalize=not no_equalize,
            grid_boundary=boundary,
            per_level=per_level,
            thresholding=thresholding,
            callback=bar,
        )
    finally:
        bar.close()
    h, w = result.image.shape[:2]
    top = result.magnitudes.max()
    sidecar = sidecar_json(
        "modify",
        outputs={"image": out_path, "magnitudes": mag_path, "source_map": map_path, "sidecar": side_path},
        inputs={"input": input_image, "exemplar": exemplar},
        method="patch_wavelet",
        params=method.get_params(),
        seed=None,
        options={
            "ratio": ratio,
            "equalize": not no_equalize,
            "boundary": boundary,
            "per_level": per_level,
            "thresholding": thresholding,
            "bit_depth": depth,
        },
    )
    with outputs:
        outputs.write_image(out_path, result.image, bit_depth=depth)
        stage_extra(outputs, mag_path, result.magnitudes, lambda m: np.sqrt(m / top) if top > 0 else m)
        stage_extra(outputs, map_path, result.source_map, lambda m: position_colors(m, image.shape[:2]))
        outputs.write_text(side_path, sidecar)
    done(quiet, None, False, f"wrote {out_path} ({w}x{h}, ratio {ratio:g}, exemplar {label}) and {side_path}")
