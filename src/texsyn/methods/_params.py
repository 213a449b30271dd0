"""Hyperparameters read from a method's ``__init__`` signature: :class:`ParamSpec`.

A method declares each hyperparameter once, in its keyword-only ``__init__``::

    def __init__(self, *, patch_size: Annotated[int, Range(2, 512)] = 32, ...)

and describes it in the ``Parameters`` section of its class docstring. :func:`read_param_specs`
turns both into :class:`ParamSpec` records, which check values given in Python
(:meth:`ParamSpec.check`) and parse values given on the command line
(:meth:`ParamSpec.parse`); ``texsyn methods``, the CLI and the report read them
(``docs/architecture.md``, "Validation").
"""

from __future__ import annotations

import inspect
import re
import typing
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._validation import OneOf, Range
from ..errors import InputError, InputTypeError

__all__ = ["ParamSpec", "docstring_params", "read_param_specs"]


@dataclass(frozen=True)
class ParamSpec:
    """A hyperparameter as read from a method's ``__init__`` signature.

    Attributes
    ----------
    name : str
    type : type
        ``bool``, ``int``, ``float``, ``str`` or ``tuple`` (one or several numbers).
    default : object
    allowed : Range or OneOf or None
        The allowed values (each number of a tuple).
    optional : bool
        ``None`` is allowed.
    description : str
        The first sentence of the docstring entry.

    Examples
    --------
    >>> spec = ParamSpec("patch_size", int, 32, Range(2, 512), False, "Patch side.")
    >>> spec.check(12.0, "quilting")
    12
    >>> spec.parse("40", "quilting")
    40
    """

    name: str
    type: type
    default: Any
    allowed: Range | OneOf | None
    optional: bool
    description: str

    def describe_allowed(self) -> str:
        """The allowed values in words, for error messages and ``texsyn methods``."""
        parts = []
        if self.type is tuple:
            each = f" in {self.allowed.describe()}" if self.allowed is not None else ""
            parts.append(f"a number or comma-separated numbers{each}")
        elif self.allowed is not None:
            parts.append(self.allowed.describe())
        elif self.type is bool:
            parts.append("true or false")
        else:
            parts.append(self.type.__name__)
        if self.optional:
            parts.append("or none")
        return " ".join(parts)

    def text(self, value: Any) -> str:
        """``value`` as the command line writes it, which :meth:`parse` reads back exactly
        (floats as their shortest round-trip form).

        >>> ParamSpec("boundary_cut", bool, True, None, False, "").text(True)
        'true'
        >>> ParamSpec("sigma", tuple, (0.0, 0.3), None, False, "").text((0.0, 0.3))
        '0.0,0.3'
        """
        if value is None:
            return "none"
        if isinstance(value, (bool, np.bool_)):
            return "true" if value else "false"
        if isinstance(value, tuple):
            return ",".join(self.text(v) for v in value)
        if isinstance(value, (float, np.floating)):
            return repr(float(value))
        return str(value)

    def check(self, value: Any, method: str) -> Any:
        """Validate (and lightly coerce, e.g. int to float) one value; return it."""
        where = f"parameter {self.name!r} of method {method!r}"
        if value is None:
            if self.optional:
                return None
            raise InputError(f"{where} must be {self.describe_allowed()}, got None")
        kind = self.type
        if kind is bool:
            if not isinstance(value, (bool, np.bool_)):
                raise InputTypeError(f"{where} must be true or false, got {value!r}")
            value = bool(value)
        elif kind is int:
            if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
                if isinstance(value, (float, np.floating)) and float(value).is_integer():
                    value = int(value)
                else:
                    raise InputTypeError(f"{where} must be an integer, got {value!r}")
            value = int(value)
        elif kind is float:
            if isinstance(value, (bool, np.bool_)) or not isinstance(
                value, (int, float, np.integer, np.floating)
            ):
                raise InputTypeError(f"{where} must be a number, got {value!r}")
            value = float(value)
            if not np.isfinite(value):
                raise InputError(f"{where} must be finite, got {value!r}")
        elif kind is str:
            if not isinstance(value, str):
                raise InputTypeError(f"{where} must be a string, got {value!r}")
        elif kind is tuple:
            return self._check_numbers(value, where)
        if self.allowed is not None and not self.allowed.contains(value):
            raise InputError(f"{where} must be in {self.allowed.describe()}, got {value!r}")
        return value

    def _check_numbers(self, value: Any, where: str) -> tuple[float, ...]:
        """A number or a non-empty sequence of numbers, each finite and allowed."""
        items = [value] if np.ndim(value) == 0 else list(np.ravel(np.asarray(value, dtype=object)))
        if not items:
            raise InputError(f"{where} must be {self.describe_allowed()}, got an empty list")
        out = []
        for item in items:
            if isinstance(item, (bool, np.bool_)) or not isinstance(
                item, (int, float, np.integer, np.floating)
            ):
                raise InputTypeError(f"{where} must be {self.describe_allowed()}, got {value!r}")
            x = float(item)
            if not np.isfinite(x) or (self.allowed is not None and not self.allowed.contains(x)):
                raise InputError(f"{where} must be {self.describe_allowed()}, got {value!r}")
            out.append(x)
        return tuple(out)

    def parse(self, text: str, method: str) -> Any:
        """Convert a command-line string to this parameter's type, then :meth:`check` it."""
        where = f"parameter {self.name!r} of method {method!r}"
        low = text.strip().lower()
        if self.optional and low in ("none", "auto", ""):
            return None
        try:
            if self.type is bool:
                if low in ("1", "true", "yes", "on"):
                    value: Any = True
                elif low in ("0", "false", "no", "off"):
                    value = False
                else:
                    raise ValueError
            elif self.type is int:
                value = int(text)
            elif self.type is float:
                value = float(text)
            elif self.type is tuple:
                value = tuple(float(part) for part in text.split(","))
            else:
                value = text
        except ValueError:
            raise InputError(f"{where} must be {self.describe_allowed()}, got {text!r}") from None
        return self.check(value, method)


def docstring_params(doc: str | None) -> dict[str, str]:
    """First sentence of each entry of a numpydoc ``Parameters`` section.

    Examples
    --------
    >>> docstring_params('''Summary.
    ...
    ... Parameters
    ... ----------
    ... size : int
    ...     Side in pixels. Must be even.
    ... ''')
    {'size': 'Side in pixels.'}
    """
    if not doc:
        return {}
    text = inspect.cleandoc(doc)
    match = re.search(r"^Parameters\n-+\n(.*?)(?:\n\n[A-Z][A-Za-z ]+\n-+\n|\Z)", text, re.S | re.M)
    if not match:
        return {}
    out: dict[str, str] = {}
    name = None
    lines: list[str] = []
    for line in match.group(1).splitlines():
        head = re.match(r"^(\w+)\s*:", line)
        if head and not line.startswith(" "):
            if name:
                out[name] = " ".join(lines)
            name, lines = head.group(1), []
        elif name and line.strip():
            lines.append(line.strip())
    if name:
        out[name] = " ".join(lines)
    out = {k: v.replace("``", "") for k, v in out.items()}
    return {k: re.split(r"(?<=\.)\s(?=[A-Z])", v, maxsplit=1)[0] for k, v in out.items()}


def read_param_specs(init: Callable[..., None], doc: str | None) -> dict[str, ParamSpec]:
    """The :class:`ParamSpec` of every keyword of ``init``, described by ``doc``.

    Parameters
    ----------
    init : callable
        A method's ``__init__`` (annotations may use ``Annotated[..., Range(...)]``).
    doc : str or None
        The class docstring, whose ``Parameters`` section gives the descriptions.

    Returns
    -------
    dict of str to ParamSpec, in signature order.
    """
    sig = inspect.signature(init)
    hints = typing.get_type_hints(init, include_extras=True)
    docs = docstring_params(doc)
    specs = {}
    for pname, param in sig.parameters.items():
        if pname == "self" or param.kind in (param.VAR_KEYWORD, param.VAR_POSITIONAL):
            continue
        hint = hints.get(pname, type(param.default))
        allowed = None
        if typing.get_origin(hint) is typing.Annotated:
            base, *extras = typing.get_args(hint)
            allowed = next((e for e in extras if isinstance(e, (Range, OneOf))), None)
        else:
            base = hint
        if typing.get_origin(base) is tuple:
            base = tuple
        optional = False
        args = typing.get_args(base)
        if args and type(None) in args:
            optional = True
            base = next(a for a in args if a is not type(None))
        specs[pname] = ParamSpec(
            name=pname,
            type=base,
            default=param.default,
            allowed=allowed,
            optional=optional,
            description=docs.get(pname, ""),
        )
    return specs
