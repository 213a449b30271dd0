"""Materials on the command line: bit depths, value ranges, ICC profiles, stacks and replay.

``texsyn synth`` calls :func:`plan_exemplar` (the output's bit depth from ``--bit-depth`` and
the exemplar's header), :func:`read_exemplar` (the samples as stored, their
:class:`~texsyn.ops.materials.LayerEncoding`, the ICC profile) and, when the exemplar has an
alpha channel or ``--with`` images are given, :func:`synth_material`; ``texsyn replay``
(:mod:`texsyn.cli.replaying`) shares :func:`stored_image` and :func:`output_folder`. See
``docs/materials.md``.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import click
import numpy as np

from .. import data
from ..errors import InputError
from ..io import ImageFile, read_image_file, read_image_header, sidecar_path
from ..io.writing import JSON_FORMATS, WRITE_FORMATS
from ..materials import synthesize_stack
from ..ops.canvas import default_output_shape, prepare_exemplar
from ..ops.materials import LayerEncoding, is_normal_name
from ..ops.positions import position_colors
from .common import (
    check_memory_before_reading,
    claim_extra,
    done,
    draw_seed,
    input_path,
    output_set,
    sidecar_json,
    stage_extra,
)
from .options import BUILTIN_PREFIX, MAX_SIDE
from .progress import ProgressBar

__all__ = [
    "BIT_DEPTHS",
    "ExemplarPlan",
    "claim_stack_outputs",
    "claimed_depth",
    "Layer",
    "depth_name",
    "output_folder",
    "plan_exemplar",
    "read_exemplar",
    "resolve_depth",
    "stack_layers",
    "stack_output_path",
    "stored_image",
    "output_shape",
    "synth_bit_depth_option",
    "synth_material",
    "to_stored",
]

#: the values of ``texsyn synth --bit-depth``
BIT_DEPTHS = ("auto", "8", "16", "32f")
#: formats that hold float samples
FLOAT_FORMATS = (".tif", ".tiff", ".npy", ".exr")
#: formats that hold an alpha channel
ALPHA_FORMATS = (".png", ".tif", ".tiff", ".npy", ".exr")

#: ``--bit-depth auto|8|16|32f`` of ``texsyn synth``
synth_bit_depth_option = click.option(
    "--bit-depth",
    type=click.Choice(BIT_DEPTHS),
    default="auto",
    show_default=True,
    help="Output samples: 8 or 16-bit integers, 32-bit float (32f: .tif, .npy, .exr), or auto: the exemplar's (docs/materials.md).",
)


def depth_name(depth: int) -> int | str:
    """How sidecars and messages write a depth: 8, 16 or ``'32f'``."""
    return "32f" if depth == 32 else depth


def resolve_depth(choice: str, input_depth: int, path: Path, what: str = "output") -> int:
    """The bit depth of an output: the choice, or with ``auto`` the input's where the format holds it.

    ``auto``: a 16-bit input gives 16 bits (8 for JPEG, which has no 16-bit samples), a float
    input gives float in ``.tif``, ``.npy`` and ``.exr``; PNG and JPEG hold no float, so a
    float input needs ``--bit-depth 8`` or ``16`` there (its values are then written
    normalised, ``docs/materials.md``); ``.npy`` and ``.exr`` outputs of an 8-bit input are
    8-bit integers and float.
    """
    suffix = path.suffix.lower()
    allowed = WRITE_FORMATS.get(suffix, (8,))
    if choice != "auto":
        return 32 if choice == "32f" else int(choice)
    if input_depth == 32 and 32 not in allowed:
        raise InputError(
            f"the exemplar holds floating-point samples and {what} '{path}' cannot: write .tif, .npy "
            "or .exr, or give --bit-depth 16 (values written normalised to [0, 1])"
        )
    if input_depth in allowed:
        return input_depth
    return max(d for d in allowed if d <= max(input_depth, min(allowed))) if allowed else 8


def claimed_depth(choice: str, output: str) -> int:
    """The depth an output is claimed with before the exemplar's header is read: the choice,
    or with ``auto`` one its format holds (:func:`resolve_depth` decides once it is read)."""
    if choice != "auto":
        return 32 if choice == "32f" else int(choice)
    return WRITE_FORMATS.get(Path(output).suffix.lower(), (8,))[0]


def _header_depth(bits: int) -> int:
    return 32 if bits >= 32 else (16 if bits > 8 else 8)


@dataclass(frozen=True)
class ExemplarPlan:
    """What the header of an exemplar file says before its pixels are read."""

    depth: int
    channels: int


def plan_exemplar(exemplar: str | None) -> ExemplarPlan:
    """Bit depth (8, 16, 32 for float) and channels of an exemplar argument, from its header."""
    path = input_path(exemplar)
    if path is None:
        return ExemplarPlan(8, 1)
    header = read_image_header(path)
    return ExemplarPlan(_header_depth(header.bit_depth), header.channels)


@dataclass
class Layer:
    """One image of a material: where it comes from and goes to, and how its values are coded."""

    source: str
    image: np.ndarray
    depth: int
    icc_profile: bytes | None = None
    normal: bool = False
    output: Path | None = None
    out_depth: int = 8
    encoding: LayerEncoding = field(default_factory=LayerEncoding)

    def record(self) -> dict:
        out = {"input": self.source, "output": str(self.output), "bit_depth": depth_name(self.out_depth)}
        if self.normal:
            out["normal"] = True
        return out | self.encoding.record()


def read_exemplar(exemplar: str | None, preparation: dict) -> tuple[ImageFile, str]:
    """The exemplar's samples as stored (alpha kept, floats in their range:
    :func:`texsyn.data.read_exemplar`), cropped or shrunk as ``preparation`` says, and how
    messages name it."""
    found, label = data.read_exemplar(exemplar)
    image = prepare_exemplar(found.pixels, **preparation)
    return ImageFile(image, found.bit_depth, found.format, found.icc_profile), label


def to_stored(values: np.ndarray, encoding: LayerEncoding, depth: int) -> np.ndarray:
    """Method output in [0, 1] as the file stores it: back through ``encoding`` (sRGB
    encoding, then the image's value range) for a float output; an integer output keeps the
    values normalised to [0, 1] (the sidecar's ``value_range`` maps them back). The method's
    own output when the encoding is the identity (the same bytes as before materials)."""
    if encoding.is_identity:
        return values
    if depth == 32:
        return encoding.from_unit(values).astype(np.float32)
    return np.clip(LayerEncoding(linear=encoding.linear).from_unit(values), 0.0, 1.0)


def stored_image(image: np.ndarray, encoding: LayerEncoding, depth: int) -> np.ndarray:
    """An image in its own values as a file of ``depth`` stores it: float32 as is; for 8 and
    16 bits, normalised from the encoding's value range to [0, 1] (identity for images in
    [0, 1])."""
    if depth == 32:
        return np.asarray(image, dtype=np.float32)
    return np.clip(LayerEncoding(encoding.low, encoding.high).to_unit(image), 0.0, 1.0)


# ---------------------------------------------------------------------------- stacks
def stack_output_path(folder: Path, source: str) -> Path:
    """``folder / NAME`` for an input ``.../NAME``; a format texsyn does not write becomes PNG."""
    name = Path(source).name if not source.startswith(BUILTIN_PREFIX) else source.split(":", 1)[1] + ".png"
    p = Path(name)
    return folder / (p.name if p.suffix.lower() in WRITE_FORMATS else p.stem + ".png")


def stack_layers(
    exemplar: str | None, found: ImageFile, extras: list[str], normals: list[str], preparation: dict
) -> list[Layer]:
    """The guide and every ``--with`` / ``--with-normal`` image, read and prepared."""
    guide = Layer(exemplar or f"{BUILTIN_PREFIX}brick", found.pixels, found.bit_depth, found.icc_profile)
    layers = [guide]
    for path, normal in [(p, False) for p in extras] + [(p, True) for p in normals]:
        read = read_image_file(path)
        image = prepare_exemplar(read.pixels, **preparation)
        if image.shape[:2] != guide.image.shape[:2]:
            raise InputError(
                f"'{path}' is {read.pixels.shape[1]}x{read.pixels.shape[0]}; every image of a material "
                f"must have the exemplar's size"
            )
        is_normal = normal or is_normal_name(Path(path).name)
        if is_normal and (image.ndim != 3 or image.shape[2] != 3):
            raise InputError(f"normal map '{path}' must have three channels (x, y, z), got {image.shape}")
        layers.append(Layer(path, image, read.bit_depth, read.icc_profile, is_normal))
    return layers


def claim_stack_outputs(outputs, output: str, layers: list[Layer], bit_depth: str, folder: bool) -> Path:
    """Claim one output per layer in the folder ``output`` (:func:`output_folder` made it),
    or the file ``output`` for a guide alone (with its alpha); the guide's sidecar path is
    returned."""
    for layer in layers:
        target = stack_output_path(Path(output), layer.source) if folder else Path(output)
        layer.out_depth = resolve_depth(bit_depth, layer.depth, target)
        if (
            layer.image.ndim == 3
            and layer.image.shape[2] in (2, 4)
            and target.suffix.lower() not in ALPHA_FORMATS
        ):
            raise InputError(f"'{target}' cannot hold the alpha channel of '{layer.source}'")
        layer.output = outputs.claim(target, bit_depth=layer.out_depth)
    assert layers[0].output is not None
    return outputs.claim(sidecar_path(layers[0].output), formats=JSON_FORMATS, what="sidecar")


def output_shape(exemplar_shape: tuple[int, ...], size, scale) -> tuple[int, int]:
    """``--size``, ``--scale`` or twice the exemplar, as ``texsyn synth`` reads them."""
    if size is not None:
        return size
    if scale is None:
        return default_output_shape(exemplar_shape)
    shape = (round(exemplar_shape[0] * scale), round(exemplar_shape[1] * scale))
    if min(shape) < 1 or max(shape) > MAX_SIDE:
        raise InputError(
            f"--scale {scale:g} gives a {shape[1]}x{shape[0]} output from the "
            f"{exemplar_shape[1]}x{exemplar_shape[0]} exemplar; each side must be in [1, {MAX_SIDE}]"
        )
    return shape


def synth_material(
    *,
    exemplar: str | None,
    output: str,
    method: str,
    synthesizer,
    parameters: dict,
    size,
    scale,
    seed,
    source_map: str | None,
    preparation: dict,
    bit_depth: str,
    linear: bool,
    with_images: tuple[str, ...],
    with_normals: tuple[str, ...],
    overwrite: bool,
    quiet: bool,
    tileable: bool = False,
) -> None:
    """``texsyn synth`` of a material: the exemplar with its alpha and ``--with`` images.

    The images are read (each must have the exemplar's size), the outputs claimed (one file
    per image in the folder ``output``, or the file ``output`` for an exemplar with alpha
    alone), then :func:`texsyn.materials.synthesize_stack` synthesises them and they are
    written at their bit depths, with the source map and the sidecar, all or none.
    """
    outputs = output_set(overwrite)
    outputs.add_input(input_path(exemplar), "exemplar")
    for path in (*with_images, *with_normals):
        outputs.add_input(path, "--with image")
    folder = Path(output) if with_images or with_normals else None
    if folder is not None and folder.suffix and not folder.is_dir():
        raise InputError(f"with --with images the output is a folder (one file per image), got '{output}'")
    check_memory_before_reading(synthesizer, exemplar, size, scale, preparation=preparation)
    with output_folder(folder):
        found, label = read_exemplar(exemplar, preparation)
        layers = stack_layers(exemplar, found, list(with_images), list(with_normals), preparation)
        side_path = claim_stack_outputs(outputs, output, layers, bit_depth, folder is not None)
        map_path = claim_extra(outputs, source_map, "source map")
        shape = output_shape(found.pixels.shape, size, scale)
        seed, drawn = draw_seed(seed)
        options: dict = {"size": [shape[1], shape[0]], "linear": linear}
        if tileable:
            options["tileable"] = True
        if preparation.get("crop") is not None:
            options["exemplar_crop"] = [preparation["crop"][1], preparation["crop"][0]]
        if preparation.get("max_side") is not None:
            options["exemplar_max_side"] = preparation["max_side"]
        sidecar_args = {
            "outputs": {"image": layers[0].output, "source_map": map_path, "sidecar": side_path},
            "inputs": {
                "exemplar": exemplar or f"{BUILTIN_PREFIX}brick",
                "with": list(with_images) or None,
                "with_normal": list(with_normals) or None,
            },
            "method": method,
            "seed": seed,
            "options": options,
            "params": synthesizer.get_params(),
        }
        bar = ProgressBar(f"{method}", enabled=not quiet)
        try:
            result = synthesize_stack(
                found.pixels,
                [layer.image for layer in layers[1:]],
                method,
                shape,
                rng=seed,
                normals=[i for i, layer in enumerate(layers[1:]) if layer.normal],
                linear=linear,
                callback=bar,
                tileable=tileable,
                **parameters,
            )
        finally:
            bar.close()
        for layer, encoding in zip(layers, result.encodings):
            layer.encoding = encoding
        options.update(stack=result.how, channels=[layer.record() for layer in layers])
        sidecar = sidecar_json("synth", diagnostics=result.diagnostics, **sidecar_args)
        with outputs:
            for layer, image in zip(layers, result.images):
                assert layer.output is not None
                stored = stored_image(image, layer.encoding, layer.out_depth)
                outputs.write_image(
                    layer.output, stored, bit_depth=layer.out_depth, icc_profile=layer.icc_profile
                )
            exemplar_shape = found.pixels.shape[:2]
            if result.source_map is not None:  # --source-map is refused earlier for other methods
                stage_extra(
                    outputs, map_path, result.source_map, lambda m: position_colors(m, exemplar_shape)
                )
            outputs.write_text(side_path, sidecar)
    names = ", ".join(str(layer.output) for layer in layers)
    done(
        quiet,
        seed,
        drawn,
        f"wrote {names} ({shape[1]}x{shape[0]}, {method}, {result.how}, from {label}) and {side_path}",
    )


@contextlib.contextmanager
def output_folder(folder: Path | None) -> Iterator[None]:
    """Create the output folder of a stack if it is missing, and remove it again, empty,
    when the command fails (nothing is left of a failed command)."""
    created = folder is not None and not folder.is_dir()
    if created:
        assert folder is not None
        if folder.exists():
            raise InputError(f"output folder '{folder}' is a file")
        if not folder.parent.is_dir():
            raise InputError(f"cannot create output folder '{folder}': '{folder.parent}' does not exist")
        folder.mkdir()
    try:
        yield
    except BaseException:
        if created and folder is not None and folder.is_dir() and not any(folder.iterdir()):
            os.rmdir(folder)
        raise
