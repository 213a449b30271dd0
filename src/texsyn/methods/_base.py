"""The method contract: fit once, sample many (DESIGN.md, "Methods").

Every method is a subclass of :class:`TextureSynthesizer`. Its ``__init__`` signature is the
single place where hyperparameters, their defaults and their allowed ranges live:

    def __init__(self, *, patch_size: Annotated[int, Range(2, 512)] = 32, ...)

The command line, ``texsyn methods``, :meth:`get_params` and the report all read it.
"""

from __future__ import annotations

import functools
import inspect
import re
import typing
import warnings
from dataclasses import dataclass
from typing import Any, Callable, ClassVar

import numpy as np

from .._validation import (
    OneOf,
    Range,
    human_bytes,
    as_exemplar,
    check_memory,
    check_output_shape,
    normalize_rng,
)
from ..errors import InputError, InputTypeError
from ._memory import pixel_count, shape_dims
from ..ops.linalg import fixed_order

__all__ = ["ParamSpec", "Progress", "SynthesisResult", "TextureSynthesizer"]


@dataclass(frozen=True)
class SynthesisResult:
    """One synthesised texture and, for copy-based methods, where its pixels came from.

    Attributes
    ----------
    image : ndarray of float32, shape (H, W) or (H, W, 3)
        Values clipped to [0, 1]; same rank and channels as the exemplar.
    source_map : ndarray of int32, shape (H, W, 2), or None
        Exemplar ``(row, col)`` each output pixel was copied from; ``None`` for methods that
        do not copy pixels.
    """

    image: np.ndarray
    source_map: np.ndarray | None = None


@dataclass(frozen=True)
class Progress:
    """What a method reports to ``callback`` while it works.

    Attributes
    ----------
    stage : str
        Short name of the current stage (``"blocks"``, ``"iteration"``, ``"pixels"``...).
    done, total : int
        Work units finished so far and in all for this stage.
    image : ndarray or None
        An intermediate image, when the method has one worth showing.
    info : dict or None
        Method-specific diagnostics (codes, usage counts, energies...).
    """

    stage: str
    done: int
    total: int
    image: np.ndarray | None = None
    info: dict | None = None


@dataclass(frozen=True)
class ParamSpec:
    """A hyperparameter as read from a method's ``__init__`` signature."""

    name: str
    type: type
    default: Any
    allowed: Range | OneOf | None
    optional: bool
    description: str

    def describe_allowed(self) -> str:
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
            if isinstance(item, (bool, np.bool_)) or not isinstance(item, (int, float, np.integer, np.floating)):
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
            raise InputError(
                f"{where} must be {self.describe_allowed()}, got {text!r}"
            ) from None
        return self.check(value, method)


def _planned_exemplar_shape(image: Any) -> tuple[int, ...] | None:
    """The shape :func:`as_exemplar` would give ``image``, read without converting it.

    ``None`` when the input is not an array of a shape ``as_exemplar`` accepts (it then
    raises the precise error itself).
    """
    if isinstance(image, (str, bytes)) or not hasattr(image, "shape"):
        return None
    shape = tuple(int(s) for s in np.shape(image))
    if len(shape) == 2 and min(shape) >= 2:
        return shape
    if len(shape) == 3 and min(shape[:2]) >= 2 and shape[2] in (1, 2, 3, 4):
        channels = {1: 1, 2: 1, 3: 3, 4: 3}[shape[2]]
        return shape[:2] if channels == 1 else shape[:2] + (3,)
    return None


def _docstring_params(doc: str | None) -> dict[str, str]:
    """First sentence of each entry of a numpydoc ``Parameters`` section."""
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


class TextureSynthesizer:
    """Base class of every synthesis method.

    Subclasses define ``name``, ``summary`` and ``reference``, a keyword-only ``__init__``
    that stores its hyperparameters under the same names, ``_fit(exemplar)`` and
    ``_sample(shape, rng, callback)``.
    """

    name: ClassVar[str] = ""
    summary: ClassVar[str] = ""
    #: old parameter names still accepted, each mapped to its new name, with a
    #: DeprecationWarning (docs/architecture.md, "Vocabulary")
    deprecated_params: ClassVar[dict[str, str]] = {}
    reference: ClassVar[str] = ""
    has_source_map: ClassVar[bool] = False
    #: whether every output pixel equals the exemplar pixel its source map names
    source_map_exact: ClassVar[bool] = True
    #: rough working memory per pixel and channel, in bytes: the default of
    #: :meth:`memory_terms` for methods that do not model their memory in more detail
    bytes_per_pixel: ClassVar[float] = 256.0
    #: factor on the sum of :meth:`memory_terms` for the arrays too small to be modelled one
    #: by one and the allocator's slack; 1 MiB is added for small objects (``docs/memory.md``)
    memory_margin: ClassVar[float] = 1.25

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if cls.__dict__.get("deprecated_params") and "__init__" in cls.__dict__:
            init = cls.__dict__["__init__"]

            @functools.wraps(init)
            def __init__(self, *args: Any, **params: Any) -> None:
                init(self, *args, **type(self).canonical_params(params, stacklevel=2))

            cls.__init__ = __init__  # type: ignore[method-assign]

    @classmethod
    def canonical_params(cls, params: dict[str, Any], *, stacklevel: int = 2) -> dict[str, Any]:
        """``params`` with deprecated names replaced by their new ones (a warning each).

        Raises
        ------
        InputError
            When a parameter is given under both its old and its new name.
        """
        out = dict(params)
        for old, new in cls.deprecated_params.items():
            if old in out:
                if new in out:
                    raise InputError(
                        f"parameter {old!r} of method {cls.name!r} is the deprecated name of "
                        f"{new!r}; give only {new!r}"
                    )
                warnings.warn(
                    f"parameter {old!r} of method {cls.name!r} is deprecated; use {new!r}",
                    DeprecationWarning,
                    stacklevel=stacklevel + 1,
                )
                out[new] = out.pop(old)
        return out

    # ------------------------------------------------------------------ parameters
    @classmethod
    def param_specs(cls) -> dict[str, ParamSpec]:
        """The hyperparameters, read from the ``__init__`` signature and docstring."""
        sig = inspect.signature(cls.__init__)
        hints = typing.get_type_hints(cls.__init__, include_extras=True)
        docs = _docstring_params(cls.__doc__)
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

    def get_params(self) -> dict[str, Any]:
        """Current hyperparameters as a dict (scikit-learn style)."""
        return {name: getattr(self, name) for name in self.param_specs()}

    def _check_params(self) -> None:
        for name, spec in self.param_specs().items():
            setattr(self, name, spec.check(getattr(self, name), self.name))

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self.get_params().items())
        return f"{type(self).__name__}({args})"

    # ------------------------------------------------------------------ memory
    def memory_terms(
        self, exemplar_shape: tuple[int, ...], output_shape: tuple[int, int] | None = None
    ) -> dict[str, float]:
        """Named parts of the estimated peak memory, in bytes (``docs/memory.md``).

        The hook that methods override: each term is an array (or group of arrays) the
        method holds at its peak, computed from the shapes and the hyperparameters only,
        before any work. The default counts the float64 exemplar plus
        :attr:`bytes_per_pixel` per pixel and channel of the exemplar (fit) and of the output
        (sampling).

        Parameters
        ----------
        exemplar_shape : tuple
            ``(H, W)`` or ``(H, W, C)`` of the exemplar as :meth:`fit` sees it.
        output_shape : (int, int), optional
            ``None`` for the peak of :meth:`fit`; otherwise the peak of sampling this size
            from the fitted model (what ``fit`` keeps included).

        Returns
        -------
        dict of str to float
        """
        h, w, c = shape_dims(exemplar_shape)
        terms = {"exemplar and its statistics": (8.0 + self.bytes_per_pixel) * c * h * w}
        if output_shape is not None:
            terms["working arrays of the output"] = self.bytes_per_pixel * c * pixel_count(output_shape)
        return terms

    def estimate_memory(
        self, exemplar_shape: tuple[int, ...], output_shape: tuple[int, int] | None = None
    ) -> int:
        """Estimated peak memory of fitting, or of sampling, in bytes (``docs/memory.md``).

        :attr:`memory_margin` times the sum of :meth:`memory_terms`, plus 1 MiB: the arrays
        the method allocates (not the memory Python and the imported libraries hold anyway).
        :meth:`fit`, :meth:`sample` and the other entry points compare it with
        ``TEXSYN_MEMORY_LIMIT`` before they start.

        Parameters
        ----------
        exemplar_shape : tuple
            ``(H, W)`` or ``(H, W, C)``.
        output_shape : (int, int), optional
            ``None`` estimates :meth:`fit`; a shape estimates sampling that size.

        Returns
        -------
        int
        """
        self._check_params()
        out = None if output_shape is None else tuple(int(v) for v in tuple(output_shape)[:2])
        terms = self.memory_terms(tuple(exemplar_shape), out)
        return int(np.ceil(self._memory_total(terms)))

    def check_memory_for(
        self, exemplar_shape: tuple[int, ...], output_shape: tuple[int, int] | None = None
    ) -> None:
        """Refuse, before any data is read, work that would exceed ``TEXSYN_MEMORY_LIMIT``.

        For front doors that know the shapes first (the command line reads an image file's
        header before its pixels): checks fitting an exemplar of ``exemplar_shape`` and, when
        ``output_shape`` is given, sampling that size from it.

        Raises
        ------
        MemoryLimitError
            The estimate (:meth:`estimate_memory`) exceeds the limit.
        """
        self._check_params()
        self._check_memory(tuple(exemplar_shape))
        if output_shape is not None:
            self._check_memory(tuple(exemplar_shape), tuple(int(v) for v in tuple(output_shape)[:2]))

    def _memory_total(self, terms: dict[str, float]) -> float:
        """:attr:`memory_margin` times the terms, plus 1 MiB of small arrays and objects."""
        return self.memory_margin * float(sum(terms.values())) + 2.0**20

    def _check_memory(
        self,
        exemplar_shape: tuple[int, ...],
        output_shape: tuple[int, int] | None = None,
        *,
        task: str | None = None,
        advice: str | None = None,
        terms: dict[str, float] | None = None,
    ) -> None:
        """Raise :class:`~texsyn.errors.MemoryLimitError` when the estimate exceeds the limit."""
        if terms is None:
            terms = self.memory_terms(tuple(exemplar_shape), output_shape)
        need = self._memory_total(terms)
        main, size = max(terms.items(), key=lambda kv: kv[1])
        h, w = exemplar_shape[:2]
        if task is None:
            if output_shape is None:
                task = f"fitting a {w}x{h} exemplar"
            else:
                task = f"sampling {output_shape[1]}x{output_shape[0]} pixels from a {w}x{h} exemplar"
        if advice is None:
            advice = (
                "use a smaller exemplar or smaller parameters"
                if output_shape is None
                else "request a smaller size or smaller parameters"
            )
        check_memory(
            need,
            what=f"method {self.name!r} {task} (mostly {main}: {human_bytes(size)})",
            advice=advice,
        )

    # ------------------------------------------------------------------ fit / sample
    def min_exemplar_size(self) -> tuple[int, str]:
        """Smallest exemplar side this configuration accepts, and why."""
        return 2, "at least 2x2 pixels"

    @fixed_order
    def fit(self, exemplar: np.ndarray) -> "TextureSynthesizer":
        """Validate the exemplar and learn everything that depends only on it.

        Parameters
        ----------
        exemplar : ndarray, shape (H, W) or (H, W, 3)
            Float values in [0, 1] (uint8 and uint16 are scaled).

        Returns
        -------
        self

        Raises
        ------
        MemoryLimitError
            Before any work, when :meth:`estimate_memory` of the fit exceeds
            ``TEXSYN_MEMORY_LIMIT`` (``docs/memory.md``).
        """
        self._check_params()
        planned = _planned_exemplar_shape(exemplar)
        if planned is not None:  # before the (float64) conversion of a large array
            self._check_memory(planned)
        ex = as_exemplar(exemplar)
        side, why = self.min_exemplar_size()
        if min(ex.shape[:2]) < side:
            raise InputError(
                f"exemplar of {ex.shape[1]}x{ex.shape[0]} pixels is too small for method "
                f"{self.name!r}: {why}"
            )
        if planned != ex.shape:
            self._check_memory(ex.shape)
        self.exemplar_ = ex
        self._fit(ex)
        return self

    def _fit(self, exemplar: np.ndarray) -> None:  # pragma: no cover - trivial default
        pass

    def _require_fitted(self) -> np.ndarray:
        ex = getattr(self, "exemplar_", None)
        if ex is None:
            raise RuntimeError(f"method {self.name!r} must be fitted with fit(exemplar) first")
        return ex

    def sample(
        self,
        shape: tuple[int, int] | None = None,
        *,
        rng: None | int | np.random.Generator = None,
        callback: Callable[[Progress], None] | None = None,
    ) -> np.ndarray:
        """Draw one texture.

        Parameters
        ----------
        shape : (int, int), optional
            Output ``(height, width)``; twice the exemplar by default. Any size whose
            :meth:`estimate_memory` fits in ``TEXSYN_MEMORY_LIMIT`` is allowed.
        rng : None, int or numpy.random.Generator
            Source of randomness; the same value gives the same texture.
        callback : callable, optional
            Called with :class:`Progress` records while the method works.

        Returns
        -------
        ndarray of float32, values clipped to [0, 1], rank and channels of the exemplar.

        Raises
        ------
        MemoryLimitError
            Before any work, when the estimate exceeds the limit (``docs/memory.md``).
        """
        return self.sample_with_map(shape, rng=rng, callback=callback).image

    @fixed_order
    def sample_with_map(
        self,
        shape: tuple[int, int] | None = None,
        *,
        rng: None | int | np.random.Generator = None,
        callback: Callable[[Progress], None] | None = None,
    ) -> SynthesisResult:
        """Like :meth:`sample`, but also return the source map of copy-based methods."""
        ex = self._require_fitted()
        if shape is None:
            shape = (2 * ex.shape[0], 2 * ex.shape[1])
        out_shape = check_output_shape(shape)
        self._check_memory(ex.shape, out_shape)
        generator = normalize_rng(rng)
        image, source = self._sample(out_shape, generator, callback)
        result = self._as_output(image)
        if source is not None:
            source = np.asarray(source, dtype=np.int32)
        return SynthesisResult(image=result, source_map=source)

    def _as_output(self, image: np.ndarray) -> np.ndarray:
        """An image as methods return it: the exemplar's rank, float32 clipped to [0, 1]."""
        image = np.asarray(image)
        if image.ndim == 3 and self._require_fitted().ndim == 2:
            image = image[..., 0]
        return np.clip(image, 0.0, 1.0).astype(np.float32)

    def _sample(
        self,
        shape: tuple[int, int],
        rng: np.random.Generator,
        callback: Callable[[Progress], None] | None,
    ) -> tuple[np.ndarray, np.ndarray | None]:  # pragma: no cover - abstract
        raise NotImplementedError
