"""Checks of images, shapes, options and ranges, with messages that name the problem.

Every user-facing entry point (the methods' ``fit``/``sample``, ``texsyn.synthesize``, the
command line) validates through these helpers, so that a bad input always produces one
``ValueError`` or ``TypeError`` whose message names the parameter, what is allowed and what
was received.
"""

from __future__ import annotations

import math
import os
import re
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np

from .errors import InputError, InputTypeError, MemoryLimitError

__all__ = [
    "Range",
    "OneOf",
    "as_exemplar",
    "check_memory",
    "check_output_shape",
    "normalize_rng",
    "memory_limit_bytes",
    "parse_memory_size",
]


@dataclass(frozen=True)
class Range:
    """Allowed interval of a numeric hyperparameter, used in ``Annotated[...]`` signatures.

    Parameters
    ----------
    low, high : float or None
        Bounds; ``None`` means unbounded on that side.
    low_open, high_open : bool
        Whether the bound itself is excluded.
    """

    low: float | None = None
    high: float | None = None
    low_open: bool = False
    high_open: bool = False

    def contains(self, value: float) -> bool:
        if self.low is not None and (value < self.low or (self.low_open and value == self.low)):
            return False
        if self.high is not None and (value > self.high or (self.high_open and value == self.high)):
            return False
        return True

    def describe(self) -> str:
        left = "(" if self.low_open else "["
        right = ")" if self.high_open else "]"
        low = "-inf" if self.low is None else _fmt(self.low)
        high = "inf" if self.high is None else _fmt(self.high)
        if self.low is None:
            left = "("
        if self.high is None:
            right = ")"
        return f"{left}{low}, {high}{right}"


@dataclass(frozen=True)
class OneOf:
    """Allowed values of a categorical hyperparameter, used in ``Annotated[...]`` signatures."""

    values: tuple

    def contains(self, value: Any) -> bool:
        return value in self.values

    def describe(self) -> str:
        return "{" + ", ".join(repr(v) if isinstance(v, str) else _fmt(v) for v in self.values) + "}"


def _fmt(x: Any) -> str:
    if isinstance(x, float) and x.is_integer() and abs(x) < 1e15:
        return str(int(x))
    return str(x)


def as_exemplar(image: Any, *, name: str = "exemplar", max_channels: int = 3) -> np.ndarray:
    """Validate an exemplar array and return it as float64 ``(H, W)`` or ``(H, W, C)``.

    Accepts float arrays with values in [0, 1] and uint8/uint16 arrays (scaled to [0, 1]).
    With ``max_channels=3`` (methods that synthesise grey or colour only), a fourth (alpha)
    channel, or the second of grey + alpha, is dropped with a warning (``texsyn.synthesize``
    and ``texsyn synth`` keep it: ``docs/materials.md``); a method that synthesises ``C``
    channels jointly (its ``max_channels``) takes any ``C`` up to it. A single channel is
    squeezed.

    Raises
    ------
    TypeError
        If the input is not a numeric array.
    ValueError
        If its rank, size or values are not allowed (NaN, infinity, outside [0, 1]).
    """
    if isinstance(image, (str, os.PathLike)):
        raise InputTypeError(
            f"{name} must be an image array, got a path {str(image)!r}; "
            "read it first with texsyn.io.read_image"
        )
    try:
        arr = np.asarray(image)
    except Exception as exc:  # pragma: no cover - exotic array-likes
        raise InputTypeError(f"{name} must be an array of numbers, got {type(image).__name__}") from exc
    if arr.dtype == bool:
        arr = arr.astype(np.float64)
    if arr.dtype == np.uint8:
        arr = arr.astype(np.float64) / 255.0
    elif arr.dtype == np.uint16:
        arr = arr.astype(np.float64) / 65535.0
    elif np.issubdtype(arr.dtype, np.floating):
        arr = arr.astype(np.float64)
    elif np.issubdtype(arr.dtype, np.integer):
        raise InputTypeError(
            f"{name} must be float in [0, 1], uint8 or uint16; got integer dtype {arr.dtype}"
        )
    else:
        raise InputTypeError(f"{name} must be an array of numbers, got dtype {arr.dtype}")
    if arr.ndim == 3 and arr.shape[2] in (2, 4) and max_channels <= 3:
        if np.any(arr[..., -1] < 1.0):
            warnings.warn(
                f"{name} has a transparency channel; this method synthesises colour or grey only, "
                "so it is dropped (texsyn.synthesize keeps it: docs/materials.md)",
                UserWarning,
                stacklevel=3,
            )
        arr = arr[..., :-1]
    if arr.ndim == 3 and arr.shape[2] == 1:
        arr = arr[..., 0]
    if max_channels > 3 and arr.ndim == 3 and not 2 <= arr.shape[2] <= max_channels:
        raise InputError(
            f"{name} must have shape (H, W) or (H, W, C) with C from 2 to {max_channels}, got shape {tuple(arr.shape)}"
        )
    if arr.ndim not in (2, 3) or (arr.ndim == 3 and max_channels <= 3 and arr.shape[2] != 3):
        raise InputError(f"{name} must have shape (H, W) or (H, W, 3), got shape {tuple(arr.shape)}")
    if arr.shape[0] < 2 or arr.shape[1] < 2:
        raise InputError(f"{name} is {arr.shape[1]}x{arr.shape[0]} pixels; at least 2x2 is needed")
    if not np.all(np.isfinite(arr)):
        bad = int(np.count_nonzero(~np.isfinite(arr)))
        raise InputError(f"{name} contains {bad} NaN or infinite values; all values must be finite")
    lo, hi = float(arr.min()), float(arr.max())
    if lo < 0.0 or hi > 1.0:
        raise InputError(f"{name} values must lie in [0, 1], got values in [{lo:.4g}, {hi:.4g}]")
    return np.ascontiguousarray(arr)


#: the environment variable that sets the memory limit (``docs/memory.md``)
MEMORY_LIMIT_VARIABLE = "TEXSYN_MEMORY_LIMIT"
#: smallest and largest limit ``TEXSYN_MEMORY_LIMIT`` may set, in bytes
MEMORY_LIMIT_RANGE = (2**20, 2**60)

_SIZE_UNITS = {"": 1, "K": 2**10, "M": 2**20, "G": 2**30, "T": 2**40, "P": 2**50}
_SIZE_PATTERN = re.compile(
    r"(?P<number>(?:\d+(?:\.\d*)?|\.\d+)(?:e[+-]?\d+)?)\s*(?P<unit>[kmgtp]?)(?:i?b)?", re.IGNORECASE
)


def parse_memory_size(text: str, *, name: str = MEMORY_LIMIT_VARIABLE) -> int:
    """Bytes named by a size such as ``512M``, ``8G``, ``1.5GiB`` or ``1000000000``.

    A finite positive number of bytes with an optional suffix ``K``, ``M``, ``G``, ``T`` or
    ``P``, optionally followed by ``B`` or ``iB`` (``K``, ``KB`` and ``KiB`` all mean 1024
    bytes), case-insensitive; surrounding spaces are ignored. The result must lie in
    :data:`MEMORY_LIMIT_RANGE` (1 MiB to 2**60 bytes).

    Parameters
    ----------
    text : str
        The size as written.
    name : str
        What the size is called in the error message.

    Returns
    -------
    int
        The size in bytes (fractions of a byte are dropped).

    Raises
    ------
    InputError
        One line naming ``name``, what it got and what is allowed.
    """
    match = _SIZE_PATTERN.fullmatch(str(text).strip())
    value = float("nan")
    if match is not None:
        value = float(match.group("number")) * _SIZE_UNITS[match.group("unit").upper()]
    low, high = MEMORY_LIMIT_RANGE
    if not math.isfinite(value) or not low <= value <= high:
        raise InputError(
            f"{name} must be a size such as 512M or 8G, from 1M to 1024P (a number of bytes "
            f"with an optional K, M, G, T or P suffix), got {text!r}"
        )
    return int(value)


def memory_limit_bytes() -> int:
    """Memory a single fit, synthesis or modification may plan to use, in bytes.

    ``TEXSYN_MEMORY_LIMIT`` (see :func:`parse_memory_size`: ``512M``, ``8G``...) overrides the
    default, half of the machine's physical memory; an empty value counts as unset. Methods
    compare their estimate of the arrays they will hold (``docs/memory.md``) with it before
    they start.

    Raises
    ------
    InputError
        If ``TEXSYN_MEMORY_LIMIT`` is set to anything but an allowed size.
    """
    env = os.environ.get(MEMORY_LIMIT_VARIABLE, "")
    if env.strip():
        return parse_memory_size(env)
    try:
        return int(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") // 2)
    except (ValueError, OSError, AttributeError):  # pragma: no cover - non-POSIX
        return 8 * 2**30


def _suggest_size(need: float) -> str:
    """A value of ``TEXSYN_MEMORY_LIMIT`` a little above ``need`` bytes (e.g. ``3G``)."""
    for unit, scale in (("P", 2**50), ("T", 2**40), ("G", 2**30), ("M", 2**20)):
        if need >= scale or unit == "M":
            return f"{max(1, math.ceil(need * 1.25 / scale))}{unit}"
    return "1G"  # pragma: no cover


def check_memory(need: float, *, what: str, advice: str) -> None:
    """Refuse work whose estimated peak memory exceeds :func:`memory_limit_bytes`.

    Parameters
    ----------
    need : float
        Estimated peak bytes of the work.
    what : str
        The work, for the message (e.g. ``"method 'quilting' sampling 4000x4000 pixels"``).
    advice : str
        What the user can ask for instead (e.g. ``"request a smaller size"``).

    Raises
    ------
    MemoryLimitError
        One line with the estimate, the limit, where the limit comes from and how to change
        it.
    """
    limit = memory_limit_bytes()
    if need <= limit:
        return
    env = os.environ.get(MEMORY_LIMIT_VARIABLE, "").strip()
    source = (
        f"{MEMORY_LIMIT_VARIABLE}={env}"
        if env
        else f"default: half the RAM; {MEMORY_LIMIT_VARIABLE} is unset"
    )
    raise MemoryLimitError(
        f"{what} would need about {human_bytes(need)} of memory, more than the limit of "
        f"{human_bytes(limit)} ({source}); {advice}, or set {MEMORY_LIMIT_VARIABLE} to at "
        f"least {_suggest_size(need)} (docs/memory.md)"
    )


def human_bytes(n: float) -> str:
    for unit in ("B", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if n < 1024 or unit == "PiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n:.1f} PiB"  # pragma: no cover


def check_output_shape(
    shape: Any, *, bytes_per_pixel: float | None = None, name: str = "shape"
) -> tuple[int, int]:
    """Validate a requested output shape ``(H, W)``, optionally against the memory limit.

    Methods check their memory with :meth:`TextureSynthesizer.estimate_memory
    <texsyn.methods.TextureSynthesizer.estimate_memory>`, which knows their parameters and
    the exemplar; ``bytes_per_pixel`` is a rough check for callers that have no such
    estimate.

    Parameters
    ----------
    shape : tuple of two positive ints
        Requested output height and width (a third entry, channels, is ignored).
    bytes_per_pixel : float, optional
        Working memory per output pixel; when given, a shape whose pixels times this
        exceeds :func:`memory_limit_bytes` raises :class:`~texsyn.errors.MemoryLimitError`.
    name : str
        What the shape is called in messages.

    Returns
    -------
    (int, int)
    """
    try:
        dims = tuple(shape)
    except TypeError:
        raise InputTypeError(f"{name} must be a pair (height, width), got {shape!r}") from None
    if len(dims) == 3:
        dims = dims[:2]
    if len(dims) != 2:
        raise InputError(f"{name} must be a pair (height, width), got {shape!r}")
    out = []
    for d in dims:
        if isinstance(d, (bool, np.bool_)) or not isinstance(d, (int, np.integer)):
            if isinstance(d, (float, np.floating)) and float(d).is_integer():
                d = int(d)
            else:
                raise InputTypeError(f"{name} must hold integers, got {shape!r}")
        if d < 1:
            raise InputError(f"{name} must hold sizes of at least 1 pixel, got {shape!r}")
        out.append(int(d))
    if bytes_per_pixel is not None:
        check_memory(
            float(out[0]) * float(out[1]) * float(bytes_per_pixel),
            what=f"an output of {out[1]}x{out[0]} pixels",
            advice="request a smaller size",
        )
    return out[0], out[1]


def normalize_rng(rng: Any) -> np.random.Generator:
    """Return a ``numpy.random.Generator`` from ``None``, an int, a SeedSequence or a Generator."""
    if isinstance(rng, np.random.Generator):
        return rng
    if rng is None or isinstance(rng, (int, np.integer, np.random.SeedSequence)):
        if isinstance(rng, (int, np.integer)) and rng < 0:
            raise InputError(f"rng seed must be a non-negative integer, got {rng}")
        return np.random.default_rng(rng)
    if isinstance(rng, np.random.RandomState):
        raise InputTypeError(
            "rng must be None, an int or a numpy.random.Generator; the legacy RandomState is "
            "not accepted (texsyn never uses global random state)"
        )
    raise InputTypeError(f"rng must be None, an int or a numpy.random.Generator, got {type(rng).__name__}")
