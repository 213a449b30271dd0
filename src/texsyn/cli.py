"""The ``texsyn`` command line. It only calls the public API; options come from the registry.

Every error caused by the input (missing or unreadable file, bad size, unknown method or
parameter, value out of range, output too large, output folder missing) prints one line
``texsyn: error: ...`` on stderr and exits with status 2, without a traceback and without
creating or overwriting any output file.
"""

from __future__ import annotations

import sys
import time
import warnings
from pathlib import Path

import click
import numpy as np

from . import __version__, data
from .io import check_output_path, read_image, write_array, write_image
from .methods import METHODS, Progress, SynthesisResult, get_method, make_method
from .ops import position_colors
from .errors import InputError, InputFileNotFoundError, OutputExistsError

EXIT_BAD_INPUT = 2


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
            from rich.progress import BarColumn, Progress as RichProgress, TextColumn, TimeElapsedColumn

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


def _parse_size(text: str) -> tuple[int, int]:
    parts = text.lower().replace("×", "x").split("x")
    try:
        width, height = (int(p) for p in parts)
    except ValueError:
        raise click.BadParameter(f"size must look like WIDTHxHEIGHT (e.g. 256x256), got {text!r}") from None
    if width < 1 or height < 1:
        raise click.BadParameter(f"size must be at least 1x1, got {text!r}")
    return height, width


def _parse_params(method: str, items: tuple[str, ...]) -> dict:
    specs = get_method(method).param_specs()
    params = {}
    for item in items:
        if "=" not in item:
            raise click.BadParameter(f"parameters are given as NAME=VALUE, got {item!r}")
        name, value = item.split("=", 1)
        name = name.strip()
        if name not in specs:
            allowed = ", ".join(specs) if specs else "none"
            raise InputError(f"unknown parameter {name!r} for method {method!r}; allowed: {allowed}")
        params[name] = specs[name].parse(value, method)
    return params


def _array_or_picture_path(path: str | None) -> Path | None:
    """Check an extra output that is written as a ``.npy`` array or as a picture (PNG/JPEG/TIFF)."""
    if path is None:
        return None
    if Path(path).suffix.lower() == ".npy":
        return check_output_path(path, formats={".npy": (8,)})
    return check_output_path(path)


def _write_array_or_picture(path: Path | None, array: np.ndarray, picture) -> None:
    """Write ``array`` to a ``.npy`` path, or ``picture(array)`` (values in [0, 1]) to an image path."""
    if path is None:
        return
    if path.suffix.lower() == ".npy":
        write_array(path, array)
    else:
        write_image(path, picture(array))


def _read_flow(path: str) -> np.ndarray:
    """A flow field from a .npy array (H, W, 2) or from the red/green channels of an image."""
    if Path(path).suffix.lower() == ".npy":
        if not Path(path).is_file():
            raise InputFileNotFoundError(f"no such file: '{path}'")
        try:
            flow = np.load(path, allow_pickle=False)
        except (ValueError, OSError) as exc:
            raise InputError(f"cannot read '{path}' as a NumPy array ({exc})") from None
        if flow.ndim != 3 or flow.shape[2] != 2 or not np.issubdtype(flow.dtype, np.number):
            raise InputError(f"flow array '{path}' must have shape (H, W, 2), got {flow.shape}")
        return flow.astype(np.float64)
    picture = read_image(path)
    if picture.ndim != 3:
        raise InputError(f"flow image '{path}' must be a colour image (red = row, green = column component)")
    return 2.0 * picture[..., :2].astype(np.float64) - 1.0


def _load_exemplar(exemplar: str | None) -> tuple[np.ndarray, str]:
    if exemplar is None:
        return data.exemplar("brick"), "built-in brick"
    if exemplar.startswith("builtin:"):
        name = exemplar.split(":", 1)[1]
        return data.exemplar(name), f"built-in {name}"
    return read_image(exemplar), exemplar


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, "--version", prog_name="texsyn", message="%(prog)s %(version)s")
def cli() -> None:
    """Exemplar-based texture synthesis."""


@cli.command()
@click.argument("exemplar", required=False)
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False), help="Output image (.png, .jpg, .tif).")
@click.option("-m", "--method", default="quilting", show_default=True, help="Synthesis method (see `texsyn methods`).")
@click.option("--size", help="Output size WIDTHxHEIGHT [default: twice the exemplar].")
@click.option("--scale", type=float, help="Output size as a multiple of the exemplar size.")
@click.option("--seed", type=click.IntRange(min=0), help="Random seed; the same seed gives the same texture.")
@click.option("-p", "--param", "params", multiple=True, metavar="NAME=VALUE", help="Method parameter (repeatable).")
@click.option("--source-map", type=click.Path(dir_okay=False), help="Also write where each pixel came from (.npy array, or a .png/.tif position-colour picture).")
@click.option("--bit-depth", type=click.Choice(["8", "16"]), default="8", show_default=True, help="Bits per sample of the output (16 for PNG/TIFF).")
@click.option("--flow", "flow_file", type=click.Path(dir_okay=False), help="Flow to synthesise along (grouplets): a .npy (H, W, 2) array of (row, col) vectors, or an image whose red and green channels map [0, 1] to row and column components in [-1, 1]. The output takes its size.")
@click.option("-q", "--quiet", is_flag=True, help="No progress bar.")
def synth(exemplar, output, method, size, scale, seed, params, source_map, bit_depth, flow_file, quiet):
    """Synthesise a texture from EXEMPLAR (an image file, or builtin:brick|grass|gravel).

    Without EXEMPLAR, the built-in brick texture is used.
    """
    if size is not None and scale is not None:
        raise click.BadParameter("give either --size or --scale, not both")
    get_method(method)
    depth = int(bit_depth)
    out_path = check_output_path(output, bit_depth=depth)
    parameters = _parse_params(method, params)
    synthesizer = make_method(method, **parameters)
    map_path = None
    if source_map is not None:
        if not type(synthesizer).has_source_map:
            with_maps = ", ".join(n for n, c in sorted(METHODS.items()) if c.has_source_map)
            raise InputError(f"method {method!r} does not copy pixels, so it has no source map; methods with one: {with_maps}")
        map_path = _array_or_picture_path(source_map)
    flow = None
    if flow_file is not None:
        if not hasattr(synthesizer, "synthesize_along"):
            raise InputError(f"method {method!r} does not follow a flow; --flow needs method 'grouplets'")
        if size is not None or scale is not None:
            raise click.BadParameter("--flow sets the output size; do not give --size or --scale")
        flow = _read_flow(flow_file)
    image, label = _load_exemplar(exemplar)
    if flow is not None:
        shape = flow.shape[:2]
    elif size is not None:
        shape = _parse_size(size)
    elif scale is not None:
        if not scale > 0:
            raise click.BadParameter(f"--scale must be positive, got {scale}")
        shape = (max(1, round(image.shape[0] * scale)), max(1, round(image.shape[1] * scale)))
    else:
        shape = (2 * image.shape[0], 2 * image.shape[1])
    bar = _ProgressBar(f"{method}", enabled=not quiet)
    try:
        synthesizer.fit(image)
        if flow is not None:
            result = SynthesisResult(synthesizer.synthesize_along(flow, rng=seed, callback=bar))
        else:
            result = synthesizer.sample_with_map(shape, rng=seed, callback=bar)
    finally:
        bar.close()
    write_image(out_path, result.image, bit_depth=depth)
    _write_array_or_picture(map_path, result.source_map, lambda m: position_colors(m, image.shape[:2]))
    if not quiet:
        h, w = result.image.shape[:2]
        click.echo(f"wrote {out_path} ({w}x{h}, {method}, from {label})", err=True)


@cli.command()
@click.argument("input_image", metavar="INPUT")
@click.option("-e", "--exemplar", required=True, help="Exemplar whose patches rebuild INPUT (an image file, or builtin:brick|grass|gravel).")
@click.option("-r", "--ratio", type=float, default=0.5, show_default=True, help="Threshold as a fraction of the largest detail: 0 rebuilds INPUT, 1 is a pure synthesis.")
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False), help="Output image (.png, .jpg, .tif).")
@click.option("--magnitudes", type=click.Path(dir_okay=False), help="Also write the kept detail magnitudes packed like a wavelet transform: a .npy array, or a .png/.tif picture (square root of magnitude / largest).")
@click.option("--source-map", type=click.Path(dir_okay=False), help="Also write the exemplar position of every output pixel (.npy array, or a .png/.tif position-colour picture).")
@click.option("--no-equalize", is_flag=True, help="Do not match the exemplar's colours to INPUT first.")
@click.option("--boundary", type=click.Choice(["symmetric", "periodic"]), default="symmetric", show_default=True, help="Border rule of the transform (periodic for an INPUT that tiles).")
@click.option("--per-level", is_flag=True, help="Threshold every level against its own largest detail.")
@click.option("-p", "--param", "params", multiple=True, metavar="NAME=VALUE", help="Parameter of the patch_wavelet method (repeatable).")
@click.option("--bit-depth", type=click.Choice(["8", "16"]), default="8", show_default=True, help="Bits per sample of the output (16 for PNG/TIFF).")
@click.option("-q", "--quiet", is_flag=True, help="No progress bar.")
def modify(input_image, exemplar, ratio, output, magnitudes, source_map, no_equalize, boundary, per_level, params, bit_depth, quiet):
    """Modify the texture INPUT (an image file or builtin:NAME) toward EXEMPLAR (Peyré 2007).

    INPUT is expressed with the exemplar's patches and decomposed; wavelet details below
    RATIO times the largest are removed before rebuilding.
    """
    if not 0.0 <= ratio <= 1.0:
        raise click.BadParameter(f"--ratio must be in [0, 1], got {ratio}")
    depth = int(bit_depth)
    out_path = check_output_path(output, bit_depth=depth)
    mag_path = _array_or_picture_path(magnitudes)
    map_path = _array_or_picture_path(source_map)
    parameters = _parse_params("patch_wavelet", params)
    method = make_method("patch_wavelet", **parameters)
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
    write_image(out_path, result.image, bit_depth=depth)
    top = result.magnitudes.max()
    _write_array_or_picture(mag_path, result.magnitudes, lambda m: np.sqrt(m / top) if top > 0 else m)
    _write_array_or_picture(map_path, result.source_map, lambda m: position_colors(m, image.shape[:2]))
    if not quiet:
        h, w = result.image.shape[:2]
        click.echo(f"wrote {out_path} ({w}x{h}, ratio {ratio:g}, exemplar {label})", err=True)


VIDEO_FORMATS = (".mp4", ".gif")


@cli.command()
@click.argument("exemplar", required=False)
@click.option("-o", "--output", required=True, type=click.Path(), help="Video (.mp4, .gif) or a new folder for PNG frames.")
@click.option("--frames", type=click.IntRange(min=1, max=100000), default=60, show_default=True, help="Number of frames.")
@click.option("--fps", type=click.FloatRange(min=0.1, max=240), default=24.0, show_default=True, help="Frames per second of the video.")
@click.option("--viscosity", type=click.FloatRange(min=0.0), help="Fluid viscosity (parameter 'viscosity' of grouplets).")
@click.option("--size", help="Frame size WIDTHxHEIGHT [default: the exemplar's].")
@click.option("--seed", type=click.IntRange(min=0), help="Random seed; the same seed gives the same animation.")
@click.option("--loop", type=click.IntRange(min=0), default=0, show_default=True, help="Cross-fade this many extra frames so the video loops seamlessly.")
@click.option("-p", "--param", "params", multiple=True, metavar="NAME=VALUE", help="Parameter of the grouplets method (repeatable).")
@click.option("-q", "--quiet", is_flag=True, help="No progress bar.")
def animate(exemplar, output, frames, fps, viscosity, size, seed, loop, params, quiet):
    """Animate EXEMPLAR with fluid dynamics (Peyré 2008, grouplets): write a video or frames.

    EXEMPLAR is an image file or builtin:brick|grass|gravel (default: brick). An oriented
    texture (wood, fibres, waves) works best.
    """
    from .io import write_frames

    out_path = Path(output)
    suffix = out_path.suffix.lower()
    if suffix and suffix not in VIDEO_FORMATS:
        raise InputError(f"cannot write {suffix!r} animations; use .mp4, .gif or a folder name (PNG frames)")
    if not out_path.parent.exists():
        raise InputFileNotFoundError(f"no such folder: '{out_path.parent}'")
    if not suffix and out_path.exists() and (not out_path.is_dir() or any(out_path.iterdir())):
        raise OutputExistsError(f"'{out_path}' exists and is not an empty folder")
    if loop and loop >= frames:
        raise click.BadParameter(f"--loop must be smaller than --frames ({frames}), got {loop}")
    parameters = _parse_params("grouplets", params)
    if viscosity is not None:
        parameters["viscosity"] = get_method("grouplets").param_specs()["viscosity"].check(viscosity, "grouplets")
    method = make_method("grouplets", **parameters)
    image, label = _load_exemplar(exemplar)
    shape = _parse_size(size) if size is not None else None
    bar = _ProgressBar("animate", enabled=not quiet)
    try:
        method.fit(image)
        sequence = (f.image for f in method.animate(frames, shape, rng=seed, callback=bar, loop=loop))
        write_frames(out_path, sequence, fps=fps)
    finally:
        bar.close()
    if not quiet:
        click.echo(f"wrote {out_path} ({frames} frames at {fps:g} fps, from {label})", err=True)


@cli.command()
@click.argument("exemplar", required=False)
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False), help="Report file (.html); a .json sidecar is written beside it.")
@click.option("-m", "--method", "methods", multiple=True, help="Method to compare (repeatable; all methods by default).")
@click.option("--seeds", type=click.IntRange(min=1, max=100), default=1, show_default=True, help="Syntheses per method (seeds 0..N-1).")
@click.option("--size", help="Output size WIDTHxHEIGHT [default: twice the exemplar].")
@click.option("-p", "--param", "params", multiple=True, metavar="METHOD.NAME=VALUE", help="Method parameter (repeatable).")
@click.option("--overwrite", is_flag=True, help="Replace an existing report.")
@click.option("-q", "--quiet", is_flag=True, help="No progress bar.")
def compare(exemplar, output, methods, seeds, size, params, overwrite, quiet):
    """Run several methods on EXEMPLAR and write an HTML report with metrics and timings."""
    from .report import run_comparison, write_report

    names = list(dict.fromkeys(methods)) or sorted(METHODS)
    for name in names:
        get_method(name)
    html_path = check_output_path(output, formats={".html": (8,), ".htm": (8,)})
    if not overwrite:
        for p in (html_path, html_path.with_suffix(".json")):
            if p.exists():
                raise OutputExistsError(f"'{p}' already exists; use --overwrite to replace it")
    overrides: dict[str, dict] = {}
    for item in params:
        key = item.split("=", 1)[0]
        if "." not in key or "=" not in item:
            raise click.BadParameter(f"parameters are given as METHOD.NAME=VALUE, got {item!r}")
        method, rest = item.split(".", 1)
        if method not in names:
            raise InputError(f"parameter {item!r} names method {method!r}, which is not compared")
        overrides.setdefault(method, {}).update(_parse_params(method, (rest,)))
    image, label = _load_exemplar(exemplar)
    shape = _parse_size(size) if size is not None else None
    bar = _ProgressBar("compare", enabled=not quiet, delay=0.0)
    try:
        report = run_comparison(image, names, seeds=seeds, shape=shape, exemplar_name=label, params=overrides, callback=bar)
    finally:
        bar.close()
    html_out, json_out = write_report(report, html_path, overwrite=overwrite)
    failed = [r.method for r in report.records if r.error]
    if not quiet:
        click.echo(f"wrote {html_out} and {json_out}" + (f"; failed: {', '.join(failed)}" if failed else ""), err=True)


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


def _one_line(exc: BaseException) -> str:
    text = str(exc).strip() or type(exc).__name__
    if isinstance(exc, (FileNotFoundError, PermissionError, IsADirectoryError)) and exc.filename and not str(exc).startswith(("no such", "cannot")):
        text = f"{exc.strerror or 'cannot access'}: '{exc.filename}'"
    return " ".join(text.split())


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``texsyn`` console script."""

    def show_warning(message, category, filename, lineno, file=None, line=None):
        sys.stderr.write(f"texsyn: warning: {message}\n")

    warnings.showwarning = show_warning
    try:
        code = cli.main(args=argv, prog_name="texsyn", standalone_mode=False)
    except click.exceptions.Exit as exc:
        return exc.exit_code
    except click.exceptions.Abort:
        sys.stderr.write("texsyn: interrupted\n")
        return 130
    except click.UsageError as exc:
        sys.stderr.write(f"texsyn: error: {' '.join(exc.format_message().split())}\n")
        return EXIT_BAD_INPUT
    except click.ClickException as exc:
        sys.stderr.write(f"texsyn: error: {' '.join(exc.format_message().split())}\n")
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        sys.stderr.write("texsyn: interrupted\n")
        return 130
    except (ValueError, TypeError, OSError, MemoryError) as exc:
        sys.stderr.write(f"texsyn: error: {_one_line(exc)}\n")
        return EXIT_BAD_INPUT
    return code if isinstance(code, int) else 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
