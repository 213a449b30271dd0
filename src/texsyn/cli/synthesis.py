"""The ``synth`` command (``docs/cli.md``).

It parses its options, claims every output before any work, checks the memory the work
needs from the exemplar's header, then calls the public API (``fit``, then
``sample_with_map``) with the one progress display, and writes its outputs and a JSON
sidecar all or none. ``modify`` and ``animate`` are in :mod:`~texsyn.cli.modification` and
:mod:`~texsyn.cli.animation`, so that ``synth`` loads no other method (``docs/performance.md``).
"""

from __future__ import annotations

import click
import numpy as np

from ..batch.synthesis import stream_bands
from ..errors import InputError
from ..io import sidecar_path
from ..io.writing import JSON_FORMATS
from ..methods import METHODS, SynthesisResult, get_method, make_method
from ..ops import position_colors
from ..ops.canvas import default_output_shape, prepare_exemplar
from ..ops.materials import LayerEncoding
from .common import (
    check_memory_before_reading,
    claim_extra,
    done,
    draw_seed,
    input_path,
    output_set,
    read_flow,
    sidecar_json,
    stage_extra,
)
from .materials import (
    claimed_depth,
    depth_name,
    plan_exemplar,
    read_exemplar,
    resolve_depth,
    synth_bit_depth_option,
    synth_material,
    to_stored,
)
from .options import (
    BUILTIN_PREFIX,
    MAX_SIDE,
    SIZE,
    Number,
    output_option,
    overwrite_option,
    param_option,
    parse_params,
    quiet_option,
    seed_option,
)
from .progress import ProgressBar

__all__ = ["stream_bands", "synth"]


@click.command()
@click.argument("exemplar", required=False)
@output_option("Output image (.png, .jpg, .tif, .npy, .exr), or a folder with --with.", folder=True)
@click.option(
    "-m", "--method", default="quilting", show_default=True, help="Synthesis method (see `texsyn methods`)."
)
@click.option("--size", type=SIZE, help="Output size WIDTHxHEIGHT [default: twice the exemplar].")
@click.option(
    "--scale",
    type=Number(0.0, float(MAX_SIDE), low_open=True),
    help="Output size as a multiple of the exemplar size.",
)
@seed_option("texture")
@param_option("Method parameter (repeatable).")
@click.option(
    "--source-map",
    type=click.Path(dir_okay=False),
    help="Also write where each pixel came from (.npy array, or a .png/.tif position-colour picture).",
)
@click.option(
    "--exemplar-crop",
    type=SIZE,
    metavar="WIDTHxHEIGHT",
    help="Use only the central WIDTHxHEIGHT region of EXEMPLAR (a large photo: docs/performance.md).",
)
@click.option(
    "--exemplar-max-side",
    type=click.IntRange(min=8, max=MAX_SIDE),
    metavar="N",
    help="Shrink EXEMPLAR (after --exemplar-crop) so that its longer side is at most N pixels.",
)
@synth_bit_depth_option
@click.option(
    "--linear",
    is_flag=True,
    help="Synthesise the colour in linear light: sRGB-decoded before, encoded after [default: the stored values].",
)
@click.option(
    "--with",
    "with_images",
    multiple=True,
    type=click.Path(dir_okay=False),
    metavar="IMAGE",
    help="Another image of the material (normal, height, roughness...), carried in register; -o is then a folder (repeatable; docs/materials.md).",
)
@click.option(
    "--with-normal",
    "with_normals",
    multiple=True,
    type=click.Path(dir_okay=False),
    metavar="IMAGE",
    help="A normal map of the material, renormalised to unit length (repeatable; --with takes names with 'normal' as normal maps too).",
)
@click.option(
    "--flow",
    "flow_file",
    type=click.Path(dir_okay=False),
    help="Flow to synthesise along (grouplets): a .npy (H, W, 2) array of (row, col) vectors, or an image whose red and green channels map [0, 1] to row and column components in [-1, 1]. The output takes its size.",
)
@click.option(
    "--guide-source",
    type=click.Path(dir_okay=False),
    help="Guide map of EXEMPLAR (an image of its size: labels as grey levels or colours); needs --guide-target (docs/editing.md).",
)
@click.option(
    "--guide-target",
    type=click.Path(dir_okay=False),
    help="Guide map of the output (same kind of image); the output takes its size.",
)
@click.option(
    "--guide-weight",
    type=Number(0.0, 1e6),
    help="Weight of the guides' mean squared difference against the overlap's [default: 1].",
)
@click.option(
    "--tileable",
    is_flag=True,
    help="Make the output wrap seamlessly in both directions (docs/tiling.md).",
)
@overwrite_option()
@quiet_option
def synth(
    exemplar,
    output,
    method,
    size,
    scale,
    seed,
    params,
    source_map,
    exemplar_crop,
    exemplar_max_side,
    bit_depth,
    linear,
    with_images,
    with_normals,
    flow_file,
    guide_source,
    guide_target,
    guide_weight,
    tileable,
    overwrite,
    quiet,
):
    """Synthesise a texture from EXEMPLAR (an image file, or builtin:brick|grass|gravel).

    Without EXEMPLAR, the built-in brick texture is used. Also writes OUTPUT.json.
    With --with images (a material), OUTPUT is a folder receiving one file per image.
    """
    if size is not None and scale is not None:
        raise click.UsageError("give either --size or --scale, not both")
    cls = get_method(method)
    parameters = parse_params(method, params)
    synthesizer = make_method(method, **parameters)
    if source_map is not None and not cls.has_source_map:
        with_maps = ", ".join(n for n, c in sorted(METHODS.items()) if c.has_source_map)
        raise InputError(
            f"method {method!r} does not copy pixels, so it has no source map; methods with one: {with_maps}"
        )
    if flow_file is not None:
        if not hasattr(synthesizer, "synthesize_along"):
            raise InputError(f"method {method!r} does not follow a flow; --flow needs method 'grouplets'")
        if size is not None or scale is not None:
            raise click.UsageError("--flow sets the output size; do not give --size or --scale")
    guided = guide_source is not None or guide_target is not None
    if tileable and (flow_file is not None or guided):
        raise click.UsageError("--tileable applies to a plain synthesis, not with --flow or guides")
    if guided:
        check_guide_options(method, guide_source, guide_target, size, scale, flow_file)
    elif guide_weight is not None:
        raise click.UsageError("--guide-weight needs --guide-source and --guide-target")
    guide_weight = 1.0 if guide_weight is None else guide_weight
    preparation = {"crop": exemplar_crop, "max_side": exemplar_max_side}
    material = {
        "exemplar": exemplar,
        "output": output,
        "method": method,
        "synthesizer": synthesizer,
        "parameters": parameters,
        "size": size,
        "scale": scale,
        "seed": seed,
        "source_map": source_map,
        "preparation": preparation,
        "bit_depth": bit_depth,
        "linear": linear,
        "with_images": with_images,
        "with_normals": with_normals,
        "overwrite": overwrite,
        "quiet": quiet,
        "tileable": tileable,
    }
    if with_images or with_normals:  # a material: -o is a folder (docs/materials.md)
        if flow_file is not None or guided:
            raise click.UsageError("--flow and --guide-* synthesise one image; they take no --with images")
        synth_material(**material)
        return
    outputs = output_set(overwrite)
    outputs.add_input(input_path(exemplar), "exemplar")
    outputs.add_input(flow_file, "flow file")
    outputs.add_input(guide_source, "source guide")
    outputs.add_input(guide_target, "target guide")
    out_path = outputs.claim(output, bit_depth=claimed_depth(bit_depth, output))
    map_path = claim_extra(outputs, source_map, "source map")
    side_path = outputs.claim(sidecar_path(out_path), formats=JSON_FORMATS, what="sidecar")
    plan = plan_exemplar(exemplar)
    if plan.channels in (2, 4) and flow_file is None and not guided:  # alpha carried like colour
        synth_material(**material)
        return
    depth = resolve_depth(bit_depth, plan.depth, out_path)

    flow = read_flow(flow_file) if flow_file is not None else None
    guides = read_guides(guide_source, guide_target, exemplar_crop, exemplar_max_side) if guided else None
    if guides is not None:
        size = guides[1].shape[:2]
    streaming = flow is None and guides is None and not tileable and synthesizer.streams_rows
    check_memory_before_reading(
        synthesizer,
        exemplar,
        flow.shape[:2] if flow is not None else size,
        scale,
        streaming=streaming,
        preparation=preparation,
    )
    found, label = read_exemplar(exemplar, preparation)
    encoding = LayerEncoding.of(found.pixels, linear=linear)
    image = found.pixels if encoding.is_identity else encoding.to_unit(found.pixels)
    if guides is not None:
        check_guide_sizes(guides[0], image, guide_source, exemplar)
    if flow is not None:
        shape = flow.shape[:2]
    elif size is not None:
        shape = size
    elif scale is not None:
        shape = (round(image.shape[0] * scale), round(image.shape[1] * scale))
        if min(shape) < 1 or max(shape) > MAX_SIDE:
            raise InputError(
                f"--scale {scale:g} gives a {shape[1]}x{shape[0]} output from the "
                f"{image.shape[1]}x{image.shape[0]} exemplar; each side must be in [1, {MAX_SIDE}]"
            )
    else:
        shape = default_output_shape(image.shape)
    seed, drawn = draw_seed(seed)
    h, w = shape
    options = {"size": [w, h], "bit_depth": depth_name(depth), "linear": linear}
    if encoding.low != 0.0 or encoding.high != 1.0:
        options["value_range"] = [encoding.low, encoding.high]
    if exemplar_crop is not None:
        options["exemplar_crop"] = [exemplar_crop[1], exemplar_crop[0]]
    if exemplar_max_side is not None:
        options["exemplar_max_side"] = exemplar_max_side
    if tileable:
        options["tileable"] = True
    sidecar_args = {
        "outputs": {"image": out_path, "source_map": map_path, "sidecar": side_path},
        "inputs": {
            "exemplar": exemplar or f"{BUILTIN_PREFIX}brick",
            "flow": flow_file,
            "guide_source": guide_source,
            "guide_target": guide_target,
        },
        "method": method,
        "seed": seed,
        "options": options,
    }
    bar = ProgressBar(f"{method}", enabled=not quiet)
    try:
        synthesizer.fit(image)
        if streaming:  # rows go to the files as the method finishes them (docs/performance.md)
            with outputs:
                stream_bands(
                    outputs,
                    synthesizer,
                    shape,
                    seed,
                    bar,
                    image.shape,
                    out_path,
                    map_path,
                    depth,
                    store=lambda rows: to_stored(rows, encoding, depth),
                    icc_profile=found.icc_profile,
                )
                outputs.write_text(
                    side_path, sidecar_json("synth", params=synthesizer.get_params(), **sidecar_args)
                )
        else:
            if guides is not None:
                options["guide_weight"] = guide_weight
                result = synthesizer.sample_guided(*guides, weight=guide_weight, rng=seed, callback=bar)
            elif flow is not None:
                result = SynthesisResult(synthesizer.synthesize_along(flow, rng=seed, callback=bar))
            else:
                result = synthesizer.sample_with_map(shape, rng=seed, callback=bar, tileable=tileable)
            h, w = result.image.shape[:2]
            options["size"] = [w, h]
            sidecar = sidecar_json(
                "synth", params=synthesizer.get_params(), diagnostics=result.diagnostics, **sidecar_args
            )
            with outputs:
                outputs.write_image(
                    out_path,
                    to_stored(result.image, encoding, depth),
                    bit_depth=depth,
                    icc_profile=found.icc_profile,
                )
                stage_extra(
                    outputs, map_path, result.source_map, lambda m: position_colors(m, image.shape[:2])
                )
                outputs.write_text(side_path, sidecar)
    finally:
        bar.close()
    done(quiet, seed, drawn, f"wrote {out_path} ({w}x{h}, {method}, from {label}) and {side_path}")


def check_guide_options(method, guide_source, guide_target, size, scale, flow_file) -> None:
    """Refuse guide options that cannot work together, before any file is read."""
    from ..editing import GUIDED_METHODS

    if guide_source is None or guide_target is None:
        raise click.UsageError("give both --guide-source and --guide-target")
    if method not in GUIDED_METHODS:
        raise InputError(
            f"method {method!r} does not follow guide maps; methods that do: {', '.join(GUIDED_METHODS)}"
        )
    if size is not None or scale is not None or flow_file is not None:
        raise click.UsageError("--guide-target sets the output size; do not give --size, --scale or --flow")


def read_guides(guide_source, guide_target, crop, max_side) -> tuple[np.ndarray, np.ndarray]:
    """The two guide maps, the exemplar's prepared as the exemplar is (crop, shrink)."""
    from ..io import read_image

    source = prepare_exemplar(read_image(guide_source), crop=crop, max_side=max_side)
    target = read_image(guide_target)
    if source.ndim != target.ndim:
        raise InputError("the two guides must both be grey or both colour")
    return source, target


def check_guide_sizes(source, image, guide_source, exemplar) -> None:
    """The exemplar's guide must have the exemplar's size (after --exemplar-crop/-max-side)."""
    if source.shape[:2] != image.shape[:2]:
        raise InputError(
            f"guide '{guide_source}' is {source.shape[1]}x{source.shape[0]} pixels and the exemplar "
            f"{exemplar or 'builtin:brick'} {image.shape[1]}x{image.shape[0]}; they must have the same size"
        )
