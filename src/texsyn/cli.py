"""The ``texsyn`` command line. It only calls the public API; options come from the registry.

Exit status (``docs/errors.md``):

- 0: success.
- 1: a failure that is not the user's mistake: an output could not be written (disk full,
  permission denied), the machine ran out of memory, a system error, or an internal error
  (a bug: one line, ``--debug`` shows the traceback).
- 2: bad input: a usage error or any :class:`texsyn.errors.InputError` (missing or
  unreadable file, bad size or value, unknown method or parameter, output that exists,
  names an input, or lies in a missing or read-only folder, work too large for memory).
- 130: interrupted (SIGINT, Ctrl-C); 143: terminated (SIGTERM).

Every error prints one line ``texsyn: error: ...`` on stderr. Outputs are written all or
none through :class:`texsyn.io.OutputSet`: nothing is created or replaced on any failure.
"""

from __future__ import annotations

import json
import math
import os
import re
import secrets
import shlex
import signal
import sys
import threading
import time
import traceback
import warnings
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path

import click
import numpy as np

from . import data
from ._version import __version__
from .errors import InputError, InputFileNotFoundError, OutputWriteError
from .io import OutputSet, check_image_size, max_image_pixels, read_image, read_image_header, sidecar_path
from .io.writing import ARRAY_FORMATS, JSON_FORMATS, VIDEO_FORMATS, WRITE_FORMATS
from .methods import METHODS, Progress, SynthesisResult, get_method, make_method
from .ops import position_colors

EXIT_OK = 0
EXIT_FAILURE = 1
EXIT_BAD_INPUT = 2
EXIT_INTERRUPTED = 130  # 128 + SIGINT
EXIT_TERMINATED = 143  # 128 + SIGTERM

MAX_SIDE = 100_000
"""Largest output side in pixels accepted by ``--size`` and ``--scale`` (memory is checked too)."""

BUILTIN_PREFIX = "builtin:"


class Terminated(BaseException):
    """SIGTERM arrived. Raised in the main thread (like ``KeyboardInterrupt`` for SIGINT) so
    that every ``finally``/``except BaseException`` cleanup runs and no temporary is left."""


@dataclass
class _State:
    """What :func:`main` knows about this run: the arguments and whether to show tracebacks."""

    debug: bool = False
    argv: list[str] = field(default_factory=list)


class _ProgressBar:
    """A rich progress bar on stderr that appears only once work has taken over a second."""

    def __init__(self, label: str, enabled: bool, delay: float = 1.0):
        self.label = label
        self.enabled = enabled
        self.delay = delay
        self.start = time.monotonic()
        self._bar = None
        self._task = None

    def __call__(self, progress: Progress) -> None:
        if not self.enabled:
            return
        if self._bar is None:
            if time.monotonic() - self.start < self.delay:
                return
            from rich.console import Console
            from rich.progress import BarColumn, TextColumn, TimeElapsedColumn
            from rich.progress import Progress as RichProgress

            self._bar = RichProgress(
                TextColumn("{task.description}"),
                BarColumn(),
                TextColumn("{task.completed}/{task.total}"),
                TimeElapsedColumn(),
                console=Console(stderr=True),
                transient=False,
            )
            self._bar.start()
            self._task = self._bar.add_task(self.label, total=progress.total)
        self._bar.update(
            self._task,
            completed=progress.done,
            total=progress.total,
            description=f"{self.label} ({progress.stage})",
        )

    def close(self) -> None:
        if self._bar is not None:
            self._bar.stop()
            self._bar = None


# ---------------------------------------------------------------------------- option types
class _Number(click.ParamType):
    """A finite float, optionally within bounds (click's FloatRange lets NaN through)."""

    name = "number"

    def __init__(self, low: float | None = None, high: float | None = None, *, low_open: bool = False):
        self.low, self.high, self.low_open = low, high, low_open

    def describe(self) -> str:
        if self.low is not None and self.high is not None:
            return f"{'(' if self.low_open else '['}{self.low:g}, {self.high:g}]"
        if self.low is not None:
            return f"{'>' if self.low_open else '>='} {self.low:g}"
        if self.high is not None:
            return f"<= {self.high:g}"
        return "a finite number"

    def convert(self, value, param, ctx):
        if isinstance(value, bool):
            self.fail(f"must be a number, got {value!r}", param, ctx)
        if isinstance(value, (int, float)):
            x = float(value)
        else:
            try:
                x = float(str(value).strip())
            except ValueError:
                self.fail(f"must be a number, got {value!r}", param, ctx)
        if not math.isfinite(x):
            self.fail(f"must be a finite number, got {value!r}", param, ctx)
        too_low = self.low is not None and (x <= self.low if self.low_open else x < self.low)
        too_high = self.high is not None and x > self.high
        if too_low or too_high:
            self.fail(f"must be {'in ' if self.high is not None and self.low is not None else ''}{self.describe()}, got {value!r}", param, ctx)
        return x + 0.0  # -0.0 becomes 0.0


_SIZE_RE = re.compile(r"\s*([0-9]+)\s*[xX×]\s*([0-9]+)\s*")


class _Size(click.ParamType):
    """``WIDTHxHEIGHT`` in ASCII digits, each side in [1, MAX_SIDE]; converted to ``(height, width)``."""

    name = "WIDTHxHEIGHT"

    def get_metavar(self, *args, **kwargs) -> str:
        return "WIDTHxHEIGHT"

    def convert(self, value, param, ctx):
        if isinstance(value, tuple):
            return value
        match = _SIZE_RE.fullmatch(str(value))
        if not match:
            self.fail(f"must look like WIDTHxHEIGHT (e.g. 256x256), got {value!r}", param, ctx)
        texts = match.groups()
        if any(len(t) > 9 for t in texts) or any(int(t) > MAX_SIDE for t in texts):
            self.fail(f"each side must be at most {MAX_SIDE} pixels, got {value!r}", param, ctx)
        width, height = (int(t) for t in texts)
        if width < 1 or height < 1:
            self.fail(f"must be at least 1x1, got {value!r}", param, ctx)
        return height, width


SIZE = _Size()
SEED = click.IntRange(0, 2**64 - 1)
OVERWRITE_HELP = "Replace existing output files (an output that names an input is refused anyway)."


# ---------------------------------------------------------------------------- helpers
def _parse_params(method: str, items: tuple[str, ...]) -> dict:
    specs = get_method(method).param_specs()
    params = {}
    for item in items:
        if "=" not in item:
            raise click.UsageError(f"parameters are given as NAME=VALUE, got {item!r}")
        name, value = item.split("=", 1)
        name = name.strip()
        if name not in specs:
            allowed = ", ".join(specs) if specs else "none"
            raise InputError(f"unknown parameter {name!r} for method {method!r}; allowed: {allowed}")
        params[name] = specs[name].parse(value, method)
    return params


def _input_path(name: str | None) -> str | None:
    """The file an exemplar/INPUT argument names (``None`` for the built-in textures)."""
    if name is None or name.startswith(BUILTIN_PREFIX):
        return None
    return name


def _output_set(overwrite: bool) -> OutputSet:
    return OutputSet(overwrite=overwrite, overwrite_hint="--overwrite")


def _claim_extra(outputs: OutputSet, path: str | None, what: str) -> Path | None:
    """Claim an extra output written as a ``.npy`` array or as a picture (PNG/JPEG/TIFF)."""
    if path is None:
        return None
    return outputs.claim(path, formats={**WRITE_FORMATS, **ARRAY_FORMATS}, what=what)


def _stage_extra(outputs: OutputSet, path: Path | None, array: np.ndarray, picture) -> None:
    """Stage ``array`` to a ``.npy`` path, or ``picture(array)`` (values in [0, 1]) to an image path."""
    if path is None:
        return
    if path.suffix.lower() == ".npy":
        outputs.write_array(path, array)
    else:
        outputs.write_image(path, picture(array))


def _read_flow(path: str) -> np.ndarray:
    """A flow field from a .npy array (H, W, 2) or from the red/green channels of an image."""
    if Path(path).suffix.lower() == ".npy":
        if not Path(path).is_file():
            raise InputFileNotFoundError(f"no such file: '{path}'")
        try:
            flow = np.load(path, allow_pickle=False)
        except (ValueError, OSError) as exc:
            raise InputError(f"cannot read '{path}' as a NumPy array ({' '.join(str(exc).split())})") from None
        if flow.ndim != 3 or flow.shape[2] != 2 or flow.dtype.kind not in "iuf":
            raise InputError(f"flow array '{path}' must be real numbers of shape (H, W, 2), got {flow.dtype} {flow.shape}")
        flow = flow.astype(np.float64)
        if not np.all(np.isfinite(flow)):
            raise InputError(f"flow array '{path}' holds NaN or infinite values")
        return flow
    picture = read_image(path)
    if picture.ndim != 3:
        raise InputError(f"flow image '{path}' must be a colour image (red = row, green = column component)")
    return 2.0 * picture[..., :2].astype(np.float64) - 1.0


def _planned_shape(exemplar: str | None) -> tuple[int, ...] | None:
    """The exemplar's array shape from an image file's header, before any pixel is decoded
    (``None`` for a built-in exemplar); ``TEXSYN_MAX_PIXELS`` is validated either way."""
    max_image_pixels()
    if exemplar is None or exemplar.startswith(BUILTIN_PREFIX):
        return None
    header = read_image_header(exemplar)
    check_image_size(header, exemplar, file_size=os.path.getsize(exemplar))  # the file's own limits first
    return (header.height, header.width) + ((3,) if header.channels >= 3 else ())


def _check_memory_before_reading(method, exemplar: str | None, output_shape=None, scale=None) -> None:
    """Refuse work over ``TEXSYN_MEMORY_LIMIT`` from the file's header, before decoding it
    (``docs/memory.md``); ``scale`` derives the output shape from the exemplar's."""
    planned = _planned_shape(exemplar)
    if planned is None:
        return
    if output_shape is None:
        factor = 2.0 if scale is None else float(scale)
        output_shape = (max(1, round(planned[0] * factor)), max(1, round(planned[1] * factor)))
    method.check_memory_for(planned, output_shape)


def _load_exemplar(exemplar: str | None) -> tuple[np.ndarray, str]:
    if exemplar is None:
        return data.exemplar("brick"), "built-in brick"
    if exemplar.startswith(BUILTIN_PREFIX):
        name = exemplar.split(":", 1)[1]
        return data.exemplar(name), f"built-in {name}"
    return read_image(exemplar), exemplar


def _seed(seed: int | None) -> tuple[int, bool]:
    """The seed to use and whether it was drawn (no ``--seed``): from the OS, not global state."""
    if seed is not None:
        return int(seed), False
    return secrets.randbelow(2**32), True


def _jsonable(value):
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    if isinstance(value, (str, int, float, bool)) or value is None:
        return value
    return str(value)


def _command_line() -> str:
    ctx = click.get_current_context(silent=True)
    state = ctx.find_object(_State) if ctx is not None else None
    argv = state.argv if state is not None else sys.argv[1:]
    return shlex.join(["texsyn", *argv])


def _sidecar(command: str, *, outputs: dict, inputs: dict, method: str, params: dict, seed, options: dict) -> str:
    """The JSON written beside a command's main output: enough to know and redo what made it."""
    record = {
        "texsyn_sidecar": 1,
        "texsyn_version": __version__,
        "command": command,
        "command_line": _command_line(),
        "created": datetime.now(UTC).isoformat(timespec="seconds"),
        "inputs": {k: v for k, v in inputs.items() if v is not None},
        "outputs": {k: str(v) for k, v in outputs.items() if v is not None},
        "method": method,
        "params": params,
        "seed": seed,
        "options": options,
    }
    return json.dumps(_jsonable(record), indent=2) + "\n"


def _done(quiet: bool, seed: int | None, drawn: bool, line: str) -> None:
    if quiet:
        return
    if drawn:
        click.echo(f"seed: {seed}", err=True)
    click.echo(line, err=True)


# ---------------------------------------------------------------------------- commands
def _set_debug(ctx: click.Context, param, value: bool) -> None:
    if value:
        ctx.ensure_object(_State).debug = True


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.option("--debug", is_flag=True, is_eager=True, expose_value=False, callback=_set_debug,
              help="Print the full traceback of an error (also TEXSYN_DEBUG=1).")
@click.version_option(__version__, "--version", prog_name="texsyn", message="%(prog)s %(version)s")
def cli() -> None:
    """Exemplar-based texture synthesis.

    Outputs are written all or none; an existing file is kept unless --overwrite, and an
    output never replaces an input. Each command also writes a JSON sidecar
    (OUTPUT.json: method, parameters, seed, inputs, version, command line).

    \b
    Exit status: 0 done; 1 failure that is not your input (write error, out of memory,
    internal error); 2 bad input or usage; 130 interrupted; 143 terminated.
    """


@cli.command()
@click.argument("exemplar", required=False)
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False), help="Output image (.png, .jpg, .tif).")
@click.option("-m", "--method", default="quilting", show_default=True, help="Synthesis method (see `texsyn methods`).")
@click.option("--size", type=SIZE, help="Output size WIDTHxHEIGHT [default: twice the exemplar].")
@click.option("--scale", type=_Number(0.0, float(MAX_SIDE), low_open=True), help="Output size as a multiple of the exemplar size.")
@click.option("--seed", type=SEED, help="Random seed; the same seed gives the same texture [default: drawn at random and printed].")
@click.option("-p", "--param", "params", multiple=True, metavar="NAME=VALUE", help="Method parameter (repeatable).")
@click.option("--source-map", type=click.Path(dir_okay=False), help="Also write where each pixel came from (.npy array, or a .png/.tif position-colour picture).")
@click.option("--bit-depth", type=click.Choice(["8", "16"]), default="8", show_default=True, help="Bits per sample of the output (16 for PNG/TIFF).")
@click.option("--flow", "flow_file", type=click.Path(dir_okay=False), help="Flow to synthesise along (grouplets): a .npy (H, W, 2) array of (row, col) vectors, or an image whose red and green channels map [0, 1] to row and column components in [-1, 1]. The output takes its size.")
@click.option("--overwrite", is_flag=True, help=OVERWRITE_HELP)
@click.option("-q", "--quiet", is_flag=True, help="No progress bar and no messages.")
def synth(exemplar, output, method, size, scale, seed, params, source_map, bit_depth, flow_file, overwrite, quiet):
    """Synthesise a texture from EXEMPLAR (an image file, or builtin:brick|grass|gravel).

    Without EXEMPLAR, the built-in brick texture is used. Also writes OUTPUT.json.
    """
    if size is not None and scale is not None:
        raise click.UsageError("give either --size or --scale, not both")
    cls = get_method(method)
    depth = int(bit_depth)
    parameters = _parse_params(method, params)
    synthesizer = make_method(method, **parameters)
    if source_map is not None and not cls.has_source_map:
        with_maps = ", ".join(n for n, c in sorted(METHODS.items()) if c.has_source_map)
        raise InputError(f"method {method!r} does not copy pixels, so it has no source map; methods with one: {with_maps}")
    if flow_file is not None:
        if not hasattr(synthesizer, "synthesize_along"):
            raise InputError(f"method {method!r} does not follow a flow; --flow needs method 'grouplets'")
        if size is not None or scale is not None:
            raise click.UsageError("--flow sets the output size; do not give --size or --scale")
    outputs = _output_set(overwrite)
    outputs.add_input(_input_path(exemplar), "exemplar")
    outputs.add_input(flow_file, "flow file")
    out_path = outputs.claim(output, bit_depth=depth)
    map_path = _claim_extra(outputs, source_map, "source map")
    side_path = outputs.claim(sidecar_path(out_path), formats=JSON_FORMATS, what="sidecar")

    flow = _read_flow(flow_file) if flow_file is not None else None
    _check_memory_before_reading(synthesizer, exemplar, flow.shape[:2] if flow is not None else size, scale)
    image, label = _load_exemplar(exemplar)
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
        shape = (2 * image.shape[0], 2 * image.shape[1])
    seed, drawn = _seed(seed)
    bar = _ProgressBar(f"{method}", enabled=not quiet)
    try:
        synthesizer.fit(image)
        if flow is not None:
            result = SynthesisResult(synthesizer.synthesize_along(flow, rng=seed, callback=bar))
        else:
            result = synthesizer.sample_with_map(shape, rng=seed, callback=bar)
    finally:
        bar.close()
    h, w = result.image.shape[:2]
    sidecar = _sidecar(
        "synth",
        outputs={"image": out_path, "source_map": map_path, "sidecar": side_path},
        inputs={"exemplar": exemplar or f"{BUILTIN_PREFIX}brick", "flow": flow_file},
        method=method,
        params=synthesizer.get_params(),
        seed=seed,
        options={"size": [w, h], "bit_depth": depth},
    )
    with outputs:
        outputs.write_image(out_path, result.image, bit_depth=depth)
        _stage_extra(outputs, map_path, result.source_map, lambda m: position_colors(m, image.shape[:2]))
        outputs.write_text(side_path, sidecar)
    _done(quiet, seed, drawn, f"wrote {out_path} ({w}x{h}, {method}, from {label}) and {side_path}")


@cli.command()
@click.argument("input_image", metavar="INPUT")
@click.option("-e", "--exemplar", required=True, help="Exemplar whose patches rebuild INPUT (an image file, or builtin:brick|grass|gravel).")
@click.option("-r", "--ratio", type=_Number(0.0, 1.0), default=0.5, show_default=True, help="Threshold as a fraction of the largest detail: 0 rebuilds INPUT, 1 is a pure synthesis.")
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False), help="Output image (.png, .jpg, .tif).")
@click.option("--magnitudes", type=click.Path(dir_okay=False), help="Also write the kept detail magnitudes packed like a wavelet transform: a .npy array, or a .png/.tif picture (square root of magnitude / largest).")
@click.option("--source-map", type=click.Path(dir_okay=False), help="Also write the exemplar position of every output pixel (.npy array, or a .png/.tif position-colour picture).")
@click.option("--no-equalize", is_flag=True, help="Do not match the exemplar's colours to INPUT first.")
@click.option("--boundary", type=click.Choice(["symmetric", "periodic"]), default="symmetric", show_default=True, help="Border rule of the transform (periodic for an INPUT that tiles).")
@click.option("--per-level", is_flag=True, help="Threshold every level against its own largest detail.")
@click.option("-p", "--param", "params", multiple=True, metavar="NAME=VALUE", help="Parameter of the patch_wavelet method (repeatable).")
@click.option("--bit-depth", type=click.Choice(["8", "16"]), default="8", show_default=True, help="Bits per sample of the output (16 for PNG/TIFF).")
@click.option("--overwrite", is_flag=True, help=OVERWRITE_HELP)
@click.option("-q", "--quiet", is_flag=True, help="No progress bar and no messages.")
def modify(input_image, exemplar, ratio, output, magnitudes, source_map, no_equalize, boundary, per_level, params, bit_depth, overwrite, quiet):
    """Modify the texture INPUT (an image file or builtin:NAME) toward EXEMPLAR (Peyré 2007).

    INPUT is expressed with the exemplar's patches and decomposed; wavelet details below
    RATIO times the largest are removed before rebuilding. Deterministic (no seed). Also
    writes OUTPUT.json.
    """
    depth = int(bit_depth)
    parameters = _parse_params("patch_wavelet", params)
    method = make_method("patch_wavelet", **parameters)
    outputs = _output_set(overwrite)
    outputs.add_input(_input_path(input_image), "INPUT")
    outputs.add_input(_input_path(exemplar), "exemplar")
    out_path = outputs.claim(output, bit_depth=depth)
    mag_path = _claim_extra(outputs, magnitudes, "magnitudes output")
    map_path = _claim_extra(outputs, source_map, "source map")
    side_path = outputs.claim(sidecar_path(out_path), formats=JSON_FORMATS, what="sidecar")

    _check_memory_before_reading(method, exemplar, _planned_shape(input_image))
    texture, _ = _load_exemplar(input_image)
    image, label = _load_exemplar(exemplar)
    bar = _ProgressBar("modify", enabled=not quiet)
    try:
        method.fit(image)
        result = method.modify(
            texture, ratio, equalize=not no_equalize, grid_boundary=boundary, per_level=per_level, callback=bar
        )
    finally:
        bar.close()
    h, w = result.image.shape[:2]
    top = result.magnitudes.max()
    sidecar = _sidecar(
        "modify",
        outputs={"image": out_path, "magnitudes": mag_path, "source_map": map_path, "sidecar": side_path},
        inputs={"input": input_image, "exemplar": exemplar},
        method="patch_wavelet",
        params=method.get_params(),
        seed=None,
        options={"ratio": ratio, "equalize": not no_equalize, "boundary": boundary, "per_level": per_level, "bit_depth": depth},
    )
    with outputs:
        outputs.write_image(out_path, result.image, bit_depth=depth)
        _stage_extra(outputs, mag_path, result.magnitudes, lambda m: np.sqrt(m / top) if top > 0 else m)
        _stage_extra(outputs, map_path, result.source_map, lambda m: position_colors(m, image.shape[:2]))
        outputs.write_text(side_path, sidecar)
    _done(quiet, None, False, f"wrote {out_path} ({w}x{h}, ratio {ratio:g}, exemplar {label}) and {side_path}")


@cli.command()
@click.argument("exemplar", required=False)
@click.option("-o", "--output", required=True, type=click.Path(), help="Video (.mp4, .gif) or a folder for PNG frames (new or empty).")
@click.option("--frames", type=click.IntRange(min=1, max=100000), default=60, show_default=True, help="Number of frames.")
@click.option("--fps", type=_Number(0.1, 240.0), default=24.0, show_default=True, help="Frames per second of the video.")
@click.option("--viscosity", type=_Number(0.0), help="Fluid viscosity (parameter 'viscosity' of grouplets).")
@click.option("--size", type=SIZE, help="Frame size WIDTHxHEIGHT [default: the exemplar's].")
@click.option("--seed", type=SEED, help="Random seed; the same seed gives the same animation [default: drawn at random and printed].")
@click.option("--loop", type=click.IntRange(min=0, max=100000), default=0, show_default=True, help="Cross-fade this many extra frames so the video loops seamlessly.")
@click.option("-p", "--param", "params", multiple=True, metavar="NAME=VALUE", help="Parameter of the grouplets method (repeatable).")
@click.option("--overwrite", is_flag=True, help="Replace an existing video, or a folder holding only frame_NNNNN.png files.")
@click.option("-q", "--quiet", is_flag=True, help="No progress bar and no messages.")
def animate(exemplar, output, frames, fps, viscosity, size, seed, loop, params, overwrite, quiet):
    """Animate EXEMPLAR with fluid dynamics (Peyré 2008, grouplets): write a video or frames.

    EXEMPLAR is an image file or builtin:brick|grass|gravel (default: brick). An oriented
    texture (wood, fibres, waves) works best. Also writes OUTPUT.json.
    """
    out_name = Path(output)
    suffix = out_name.suffix.lower()
    if suffix and suffix not in VIDEO_FORMATS:
        raise InputError(f"cannot write {suffix!r} animations; use .mp4, .gif or a folder name (PNG frames)")
    if loop and loop >= frames:
        raise click.UsageError(f"--loop must be smaller than --frames ({frames}), got {loop}")
    parameters = _parse_params("grouplets", params)
    if viscosity is not None:
        parameters["viscosity"] = get_method("grouplets").param_specs()["viscosity"].check(viscosity, "grouplets")
    method = make_method("grouplets", **parameters)
    outputs = _output_set(overwrite)
    outputs.add_input(_input_path(exemplar), "exemplar")
    if suffix:
        out_path = outputs.claim(out_name, formats=VIDEO_FORMATS, what="video")
    else:
        out_path = outputs.claim(out_name, folder=True, what="frame folder")
    side_path = outputs.claim(sidecar_path(out_path), formats=JSON_FORMATS, what="sidecar")

    _check_memory_before_reading(method, exemplar, size, scale=1.0)
    image, label = _load_exemplar(exemplar)
    shape = size
    seed, drawn = _seed(seed)
    bar = _ProgressBar("animate", enabled=not quiet)
    try:
        method.fit(image)
        h, w = shape if shape is not None else image.shape[:2]
        sidecar = _sidecar(
            "animate",
            outputs={"video" if suffix else "frames": out_path, "sidecar": side_path},
            inputs={"exemplar": exemplar or f"{BUILTIN_PREFIX}brick"},
            method="grouplets",
            params=method.get_params(),
            seed=seed,
            options={"frames": frames, "fps": fps, "loop": loop, "size": [w, h]},
        )
        with outputs:
            sequence = (f.image for f in method.animate(frames, shape, rng=seed, callback=bar, loop=loop))
            outputs.write_frames(out_path, sequence, fps=fps)
            outputs.write_text(side_path, sidecar)
    finally:
        bar.close()
    _done(quiet, seed, drawn, f"wrote {out_path} ({frames} frames at {fps:g} fps, from {label}) and {side_path}")


@cli.command()
@click.argument("exemplar", required=False)
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False), help="Report file (.html); a .json sidecar with the same name is written beside it.")
@click.option("-m", "--method", "methods", multiple=True, help="Method to compare (repeatable; all methods by default).")
@click.option("--seeds", type=click.IntRange(min=1, max=100), default=1, show_default=True, help="Syntheses per method (seeds 0..N-1).")
@click.option("--size", type=SIZE, help="Output size WIDTHxHEIGHT [default: twice the exemplar].")
@click.option("-p", "--param", "params", multiple=True, metavar="METHOD.NAME=VALUE", help="Method parameter (repeatable).")
@click.option("--overwrite", is_flag=True, help="Replace an existing report and its sidecar.")
@click.option("-q", "--quiet", is_flag=True, help="No progress bar and no messages.")
def compare(exemplar, output, methods, seeds, size, params, overwrite, quiet):
    """Run several methods on EXEMPLAR and write an HTML report with metrics and timings."""
    from .report import claim_report, run_comparison, write_report

    names = list(dict.fromkeys(methods)) or sorted(METHODS)
    for name in names:
        get_method(name)
    overrides: dict[str, dict] = {}
    for item in params:
        key = item.split("=", 1)[0]
        if "." not in key or "=" not in item:
            raise click.UsageError(f"parameters are given as METHOD.NAME=VALUE, got {item!r}")
        method, rest = item.split(".", 1)
        if method not in names:
            raise InputError(f"parameter {item!r} names method {method!r}, which is not compared")
        overrides.setdefault(method, {}).update(_parse_params(method, (rest,)))
    outputs = _output_set(overwrite)
    outputs.add_input(_input_path(exemplar), "exemplar")
    html_path, _ = claim_report(outputs, output)

    image, label = _load_exemplar(exemplar)
    bar = _ProgressBar("compare", enabled=not quiet, delay=0.0)
    try:
        report = run_comparison(image, names, seeds=seeds, shape=size, exemplar_name=label, params=overrides, callback=bar)
    finally:
        bar.close()
    metadata = {"texsyn_version": __version__, "command_line": _command_line(), "exemplar_path": exemplar or f"{BUILTIN_PREFIX}brick"}
    html_out, json_out = write_report(report, html_path, outputs=outputs, metadata=metadata)
    failed = [r.method for r in report.records if r.error]
    _done(quiet, None, False, f"wrote {html_out} and {json_out}" + (f"; failed: {', '.join(failed)}" if failed else ""))


@cli.command("methods")
def list_methods() -> None:
    """List the methods with their papers and parameters (defaults and allowed values)."""
    for name in sorted(METHODS):
        cls = METHODS[name]
        click.echo(f"{name}: {cls.summary}")
        click.echo(f"  paper: {cls.reference}")
        click.echo(f"  source map: {'yes' if cls.has_source_map else 'no'}")
        specs = cls.param_specs()
        if not specs:
            click.echo("  parameters: none")
        else:
            click.echo("  parameters:")
            for spec in specs.values():
                default = "none" if spec.default is None else spec.default
                if isinstance(default, tuple):
                    default = ",".join(f"{v:g}" for v in default)
                click.echo(
                    f"    {spec.name} = {default}  ({spec.type.__name__}, allowed {spec.describe_allowed()})"
                    + (f"  {spec.description}" if spec.description else "")
                )
        click.echo("")


# ---------------------------------------------------------------------------- entry point
def _one_line(text: str, limit: int = 400) -> str:
    text = " ".join(str(text).split())
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _describe_os_error(exc: OSError) -> str:
    if exc.filename and exc.strerror:
        return f"{exc.strerror}: '{exc.filename}'"
    return str(exc) or type(exc).__name__


def _report(exc: BaseException, state: _State) -> int:
    """One line on stderr for ``exc`` (the traceback first with --debug); the exit status."""
    if state.debug:
        traceback.print_exception(exc, file=sys.stderr)

    def say(line: str) -> None:
        sys.stderr.write(line.rstrip() + "\n")
        sys.stderr.flush()

    if isinstance(exc, Terminated):
        say("texsyn: terminated")
        return EXIT_TERMINATED
    if isinstance(exc, (KeyboardInterrupt, click.exceptions.Abort)):
        say("texsyn: interrupted")
        return EXIT_INTERRUPTED
    if isinstance(exc, click.ClickException):
        say(f"texsyn: error: {_one_line(exc.format_message())}")
        return EXIT_BAD_INPUT
    if isinstance(exc, InputError):
        say(f"texsyn: error: {_one_line(str(exc) or type(exc).__name__)}")
        return EXIT_BAD_INPUT
    if isinstance(exc, OutputWriteError):
        say(f"texsyn: error: {_one_line(str(exc))}")
        return EXIT_FAILURE
    if isinstance(exc, MemoryError):
        say("texsyn: error: out of memory; request a smaller output or a smaller exemplar "
            "(TEXSYN_MEMORY_LIMIT sets how much texsyn may plan to use)")
        return EXIT_FAILURE
    if isinstance(exc, OSError):
        say(f"texsyn: error: {_one_line(_describe_os_error(exc))}")
        return EXIT_FAILURE
    if isinstance(exc, SystemExit):
        return exc.code if isinstance(exc.code, int) else EXIT_FAILURE
    hint = "" if state.debug else " (run with --debug for the traceback)"
    say(f"texsyn: internal error: {type(exc).__name__}: {_one_line(str(exc), 300)}{hint}")
    return EXIT_FAILURE


def _show_warning(message, category, filename, lineno, file=None, line=None):
    sys.stderr.write(f"texsyn: warning: {_one_line(message)}\n")


def _install_signal_handlers():
    """SIGINT -> KeyboardInterrupt, SIGTERM -> Terminated, once; return a function restoring the old handlers.

    After the first signal both are ignored, so that a second one cannot interrupt the
    removal of temporary files. Signals a parent asked to ignore stay ignored.
    """
    if threading.current_thread() is not threading.main_thread():
        return lambda: None
    previous: dict[int, object] = {}

    def handler(signum, frame):
        for sig in previous:
            signal.signal(sig, signal.SIG_IGN)
        if signum == signal.SIGTERM:
            raise Terminated()
        raise KeyboardInterrupt()

    for sig in (signal.SIGINT, signal.SIGTERM):
        try:
            old = signal.getsignal(sig)
            if old is signal.SIG_IGN:
                continue
            signal.signal(sig, handler)
            previous[sig] = old
        except (ValueError, OSError):  # pragma: no cover - platforms without the signal
            pass

    def restore() -> None:
        for sig, old in previous.items():
            signal.signal(sig, old if old is not None else signal.SIG_DFL)

    return restore


def _env_flag(name: str) -> bool:
    return os.environ.get(name, "").strip().lower() in ("1", "true", "yes", "on")


def _run(args: list[str], state: _State) -> int:
    try:
        if not args:
            with click.Context(cli, info_name="texsyn") as ctx:
                click.echo(cli.get_help(ctx))
            return EXIT_OK
        with cli.make_context("texsyn", list(args), obj=state) as ctx:
            cli.invoke(ctx)
        return EXIT_OK
    except click.exceptions.Exit as exc:
        return exc.exit_code
    except BaseException as exc:  # noqa: BLE001 - every outcome becomes one line and a status
        return _report(exc, state)


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``texsyn`` console script; returns the exit status."""
    args = list(sys.argv[1:] if argv is None else argv)
    state = _State(debug=_env_flag("TEXSYN_DEBUG"), argv=[str(a) for a in args])
    saved_showwarning = warnings.showwarning
    warnings.showwarning = _show_warning
    restore = _install_signal_handlers()
    try:
        try:
            return _run(state.argv, state)
        except Terminated:  # arrived while reporting another error
            return EXIT_TERMINATED
        except KeyboardInterrupt:
            return EXIT_INTERRUPTED
    finally:
        restore()
        warnings.showwarning = saved_showwarning


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
