"""The ``animate`` command: a fluid-driven dynamic texture (Peyré 2008, grouplets) as a video.

Outputs are claimed before any work and written all or none, with a JSON sidecar, like
``synth`` (:mod:`~texsyn.cli.synthesis`).
"""

from __future__ import annotations

from pathlib import Path

import click

from ..io import sidecar_path
from ..io.output_paths import animation_format_error
from ..io.writing import JSON_FORMATS, VIDEO_FORMATS
from ..methods import make_method
from .common import (
    check_memory_before_reading,
    done,
    draw_seed,
    input_path,
    load_exemplar,
    output_set,
    sidecar_json,
)
from .options import (
    BUILTIN_PREFIX,
    SIZE,
    Number,
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

__all__ = ["ANIMATE_PARAMS", "animate"]

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
