"""Option types and method parameters of the command line (``docs/cli.md``).

Sizes are ``WIDTHxHEIGHT`` on the command line, as image tools write them, and
``(height, width)`` everywhere behind it (``docs/architecture.md``, "Vocabulary"). Method
parameters come from the registry: each method's ``__init__`` signature gives the names,
types and allowed values (:meth:`~texsyn.methods.TextureSynthesizer.param_specs`), and a
renamed parameter is still accepted under its old name with a deprecation warning.
"""

from __future__ import annotations

import math
import re

import click

from .._validation import OneOf
from ..data import BUILTIN_PREFIX
from ..errors import InputError
from ..methods import get_method

__all__ = [
    "BUILTIN_PREFIX",
    "MAX_SIDE",
    "OVERWRITE_HELP",
    "SEED",
    "SIZE",
    "Number",
    "Size",
    "bit_depth_option",
    "method_option",
    "option_params",
    "per_method_params",
    "overwrite_option",
    "param_option",
    "parse_params",
    "quiet_option",
    "seed_option",
]

MAX_SIDE = 100_000
"""Largest output side in pixels accepted by ``--size`` and ``--scale`` (memory is checked too)."""

OVERWRITE_HELP = "Replace existing output files (an output that names an input is refused anyway)."


class Number(click.ParamType):
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
            within = "in " if self.high is not None and self.low is not None else ""
            self.fail(f"must be {within}{self.describe()}, got {value!r}", param, ctx)
        return x + 0.0  # -0.0 becomes 0.0


_SIZE_RE = re.compile(r"\s*([0-9]+)\s*[xX×]\s*([0-9]+)\s*")


class Size(click.ParamType):
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


SIZE = Size()
SEED = click.IntRange(0, 2**64 - 1)


# ---------------------------------------------------------------------------- shared options
def param_option(help: str, metavar: str = "NAME=VALUE"):
    """``-p/--param NAME=VALUE``, repeatable (parsed by :func:`parse_params`)."""
    return click.option("-p", "--param", "params", multiple=True, metavar=metavar, help=help)


def seed_option(what: str):
    """``--seed N``: the same seed gives the same ``what``."""
    return click.option(
        "--seed",
        type=SEED,
        help=f"Random seed; the same seed gives the same {what} [default: drawn at random and printed].",
    )


def output_option(help: str, *, folder: bool = False):
    """``-o/--output``, required: a file (or, with ``folder``, a file or a folder)."""
    return click.option("-o", "--output", required=True, type=click.Path(dir_okay=folder), help=help)


def overwrite_option(help: str = OVERWRITE_HELP):
    """``--overwrite``: replace existing outputs (never an input)."""
    return click.option("--overwrite", is_flag=True, help=help)


#: ``--bit-depth 8|16``
bit_depth_option = click.option(
    "--bit-depth",
    type=click.Choice(["8", "16"]),
    default="8",
    show_default=True,
    help="Bits per sample of the output (16 for PNG/TIFF).",
)

#: ``-q/--quiet``
quiet_option = click.option("-q", "--quiet", is_flag=True, help="No progress bar and no messages.")


def parse_params(method: str, items: tuple[str, ...]) -> dict:
    """``NAME=VALUE`` items as a method's parameters, each parsed and checked by its spec.

    A deprecated name (a method's ``deprecated_params``) is accepted for its new name, with
    a :class:`DeprecationWarning` that the command line shows as one ``warning:`` line.

    Raises
    ------
    click.UsageError
        An item without ``=``.
    InputError
        An unknown parameter, a value its spec refuses, or a parameter given under both
        its old and its new name.
    """
    cls = get_method(method)
    specs = cls.param_specs()
    params = {}
    for item in items:
        if "=" not in item:
            raise click.UsageError(f"parameters are given as NAME=VALUE, got {item!r}")
        name, value = item.split("=", 1)
        name = name.strip()
        spec = specs.get(cls.deprecated_params.get(name, name))
        if spec is None:
            allowed = ", ".join(specs) if specs else "none"
            raise InputError(f"unknown parameter {name!r} for method {method!r}; allowed: {allowed}")
        params[name] = spec.parse(value, method)
    # stacklevel=1: the warning names this module, which the command line shows (app.main)
    return cls.canonical_params(params, stacklevel=1)


def per_method_params(items: tuple[str, ...], methods: list[str]) -> dict[str, dict]:
    """``METHOD.NAME=VALUE`` items (``compare``, ``batch``) as ``{method: parameters}``.

    Each method's values are parsed and checked by :func:`parse_params`.

    Raises
    ------
    click.UsageError
        An item not of the form ``METHOD.NAME=VALUE``.
    InputError
        An item for a method that is not among ``methods``, or a value :func:`parse_params` refuses.
    """
    overrides: dict[str, dict] = {}
    for item in items:
        key = item.split("=", 1)[0]
        if "." not in key or "=" not in item:
            raise click.UsageError(f"parameters are given as METHOD.NAME=VALUE, got {item!r}")
        method, rest = item.split(".", 1)
        if method not in methods:
            raise InputError(
                f"parameter {item!r} names method {method!r}, which is not among the methods run (-m)"
            )
        overrides.setdefault(method, {}).update(parse_params(method, (rest,)))
    return overrides


def method_option(method: str, name: str, help: str):
    """``--NAME`` (dashes for underscores) for the parameter ``name`` of ``method``.

    Its values and default are read from the signature (defaults in one place): a choice
    for a parameter with a fixed set of values, a finite number otherwise; the value is
    checked by :func:`option_params`. The option defaults to ``None``: not given, the
    method's default applies.
    """
    spec = get_method(method).param_specs()[name]
    if isinstance(spec.allowed, OneOf):
        kind: click.ParamType = click.Choice([str(v) for v in spec.allowed.values])
        allowed = ""
    else:
        kind, allowed = Number(), f", {spec.describe_allowed()}"
    return click.option(
        "--" + name.replace("_", "-"),
        name,
        type=kind,
        help=f"{help} (parameter '{name}' of {method}{allowed}) [default: {spec.text(spec.default)}]",
    )


def option_params(method: str, parameters: dict, options: dict) -> dict:
    """Add the options that set a parameter of ``method`` (:func:`method_option`) to ``parameters``.

    Parameters
    ----------
    method : str
    parameters : dict
        The ``-p NAME=VALUE`` parameters, by their current names (:func:`parse_params`).
    options : dict
        Parameter name -> option value (``None``: not given); the option is ``--NAME``
        with dashes for underscores.

    Returns
    -------
    dict
        ``parameters`` with each given option's value, checked by the parameter's spec.

    Raises
    ------
    click.UsageError
        A parameter given both by its option and by ``-p``.
    InputError
        A value the parameter's spec refuses.
    """
    specs = get_method(method).param_specs()
    for name, value in options.items():
        if value is None:
            continue
        if name in parameters:
            raise click.UsageError(f"give --{name.replace('_', '-')} or -p {name}=..., not both")
        parameters[name] = specs[name].check(value, method)
    return parameters
