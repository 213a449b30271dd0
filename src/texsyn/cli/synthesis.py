"""The synthesis commands: ``synth``, ``modify`` and ``animate`` (``docs/cli.md``).

Each command parses its options, claims every output before any work, checks the memory the
work needs from the exemplar's header, then calls the public API (``fit``, then
``sample_with_map``, ``modify`` or ``animate``) with the one progress display, and writes
its outputs and a JSON sidecar all or none.
"""

from __future__ import annotations

from pathlib import Path

import click
import numpy as np

from ..errors import InputError
from ..io import sidecar_path
from ..io.output_paths import animation_format_error
from ..io.writing import JSON_FORMATS, VIDEO_FORMATS
from ..methods import METHODS, SynthesisResult, get_method, make_method
from ..ops import position_colors
from ..ops.canvas import default_output_shape
from .common import (
    check_memory_before_reading,
    claim_extra,
    done,
    draw_seed,
    input_path,
    load_exemplar,
    output_set,
    planned_shape,
    read_flow,
    sidecar_json,
    stage_extra,
)
from .options import (
    BUILTIN_PREFIX,
    MAX_SIDE,
    SIZE,
    Number,
    bit_depth_option,
    method_option,
    option_params,
    output_option,
    overwrite_option,
    param_option,
    parse_params,
    quiet_option,
    seed_option,
)
from .progress import ProgressBar

__all__ = ["animate", "modify", "synth"]


@click.command()
@click.argument("exemplar", required=False)
@output_option("Output image (.png, .jpg, .tif).")
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
@bit_depth_option
@click.option(
    "--flow",
    "flow_file",
    type=click.Path(dir_okay=False),
    help="Flow to synthesise along (grouplets): a .npy (H, W, 2) array of (row, col) vectors, or an image whose red and green channels map [0, 1] to row and column components in [-1, 1]. The output takes its size.",
)
@overwrite_option()
@quiet_option
def synth(
    exemplar, output, method, size, scale, seed, params, source_map, bit_depth, flow_file, overwrite, quiet
):
    """Synthesise a texture from EXEMPLAR (an image file, or builtin:brick|grass|gravel).

    Without EXEMPLAR, the built-in brick texture is used. Also writes OUTPUT.json.
    """
    if size is not None and scale is not None:
        raise click.UsageError("give either --size or --scale, not both")
    cls = get_method(method)
    depth = int(bit_depth)
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
    outputs = output_set(overwrite)
    outputs.add_input(input_path(exemplar), "exemplar")
    outputs.add_input(flow_file, "flow file")
    out_path = outputs.claim(output, bit_depth=depth)
    map_path = claim_extra(outputs, source_map, "source map")
    side_path = outputs.claim(sidecar_path(out_path), formats=JSON_FORMATS, what="sidecar")

    flow = read_flow(flow_file) if flow_file is not None else None
    check_memory_before_reading(synthesizer, exemplar, flow.shape[:2] if flow is not None else size, scale)
    image, label = load_exemplar(exemplar)
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
    bar = ProgressBar(f"{method}", enabled=not quiet)
    try:
        synthesizer.fit(image)
        if flow is not None:
            result = SynthesisResult(synthesizer.synthesize_along(flow, rng=seed, callback=bar))
        else:
            result = synthesizer.sample_with_map(shape, rng=seed, callback=bar)
    finally:
        bar.close()
    h, w = result.image.shape[:2]
    sidecar = sidecar_json(
        "synth",
        outputs={"image": out_path, "source_map": map_path, "sidecar": side_path},
        inputs={"exemplar": exemplar or f"{BUILTIN_PREFIX}brick", "flow": flow_file},
        method=method,
        params=synthesizer.get_params(),
        seed=seed,
        options={"size": [w, h], "bit_depth": depth},
        diagnostics=result.diagnostics,
    )
    with outputs:
        outputs.write_image(out_path, result.image, bit_depth=depth)
        stage_extra(outputs, map_path, result.source_map, lambda m: position_colors(m, image.shape[:2]))
        outputs.write_text(side_path, sidecar)
    done(quiet, seed, drawn, f"wrote {out_path} ({w}x{h}, {method}, from {label}) and {side_path}")


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


#: the options of ``animate`` that set a parameter of grouplets, each named after it
ANIMATE_PARAMS = ("speed", "turbulence", "viscosity", "initial_flow")


@click.command()
@click.argument("exemplar", required=False)
@output_option(f"Video ({', '.join(VIDEO_FORMATS)}) or a folder for PNG frames (new or empty).", folder=True)
@click.option(
    "--frames",
    type=click.IntRange(min=1, max=100000),
    default=60,
    show_default=True,
    help="Number of frames.",
)
@click.option(
    "--fps", type=Number(0.1, 240.0), default=24.0, show_default=True, help="Frames per second of the video."
)
@method_option("grouplets", "speed", "Root-mean-square motion of the texture in pixels per frame")
@method_option(
    "grouplets",
    "turbulence",
    "Forcing that keeps the flow evolving: the fraction of its speed added per frame",
)
@method_option(
    "grouplets", "viscosity", "Fluid viscosity in pixels^2 per time unit: higher damps the small eddies"
)
@method_option("grouplets", "initial_flow", "The flow at the first frame")
@click.option("--size", type=SIZE, help="Frame size WIDTHxHEIGHT [default: the exemplar's].")
@seed_option("animation")
@click.option(
    "--loop",
    metavar="N",
    type=click.IntRange(min=0, max=100000),
    default=0,
    show_default=True,
    help="Make the sequence loop seamlessly: the simulation steers the flow back to its start "
    "over the last N frames (the last frame leads into the first). Smaller than --frames; "
    "0: no loop.",
)
@param_option("Parameter of the grouplets method (repeatable).")
@overwrite_option("Replace an existing video, or a folder holding only frame_NNNNN.png files.")
@quiet_option
def animate(
    exemplar,
    output,
    frames,
    fps,
    speed,
    turbulence,
    viscosity,
    initial_flow,
    size,
    seed,
    loop,
    params,
    overwrite,
    quiet,
):
    """Animate EXEMPLAR with fluid dynamics (Peyré 2008, grouplets): write a video or frames.

    EXEMPLAR is an image file or builtin:brick|grass|gravel (default: brick). An oriented
    texture (wood, fibres, waves) works best. --speed, --turbulence, --viscosity and
    --initial-flow set the grouplets parameters of those names (not also with -p). Also
    writes OUTPUT.json.
    """
    out_name = Path(output)
    suffix = out_name.suffix.lower()
    if suffix and suffix not in VIDEO_FORMATS:
        raise animation_format_error(suffix)
    if loop and loop >= frames:
        raise click.UsageError(f"--loop must be smaller than --frames ({frames}), got {loop}")
    given = dict(zip(ANIMATE_PARAMS, (speed, turbulence, viscosity, initial_flow), strict=True))
    parameters = option_params("grouplets", parse_params("grouplets", params), given)
    method = make_method("grouplets", **parameters)
    outputs = output_set(overwrite)
    outputs.add_input(input_path(exemplar), "exemplar")
    if suffix:
        out_path = outputs.claim(out_name, formats=VIDEO_FORMATS, what="video")
    else:
        out_path = outputs.claim(out_name, folder=True, what="frame folder")
    side_path = outputs.claim(sidecar_path(out_path), formats=JSON_FORMATS, what="sidecar")

    check_memory_before_reading(method, exemplar, size, scale=1.0)
    image, label = load_exemplar(exemplar)
    shape = size
    seed, drawn = draw_seed(seed)
    bar = ProgressBar("animate", enabled=not quiet)
    try:
        method.fit(image)
        h, w = shape if shape is not None else image.shape[:2]
        used = method.get_params()
        sidecar = sidecar_json(
            "animate",
            outputs={"video" if suffix else "frames": out_path, "sidecar": side_path},
            inputs={"exemplar": exemplar or f"{BUILTIN_PREFIX}brick"},
            method="grouplets",
            params=used,
            seed=seed,
            options={
                "frames": frames,
                "fps": fps,
                "loop": loop,
                "size": [w, h],
                **{name: used[name] for name in ANIMATE_PARAMS},
            },
        )
        with outputs:
            sequence = (f.image for f in method.animate(frames, shape, rng=seed, callback=bar, loop=loop))
            outputs.write_frames(out_path, sequence, fps=fps)
            outputs.write_text(side_path, sidecar)
    finally:
        bar.close()
    done(
        quiet, seed, drawn, f"wrote {out_path} ({frames} frames at {fps:g} fps, from {label}) and {side_path}"
    )
