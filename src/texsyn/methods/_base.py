"""The method contract: fit once, sample many (``docs/architecture.md``, "methods").

Every method is a subclass of :class:`TextureSynthesizer`. Its ``__init__`` signature is the
single place where hyperparameters, their defaults and their allowed ranges live:

    def __init__(self, *, patch_size: Annotated[int, Range(2, 512)] = 32, ...)

The command line, ``texsyn methods``, :meth:`get_params` and the report all read it
(:class:`~texsyn.methods._params.ParamSpec`). ``fit`` stores everything ``sample`` needs in
attributes ending in ``_``; ``sample`` never changes them, and :func:`texsyn.save` /
:func:`texsyn.load` keep them in a file (``docs/persistence.md``).

Why this module is long: it is the whole contract every method inherits (parameters and
their checks, fitting, the memory check, sampling with its result, persistence hooks), and
splitting it would scatter one class over several files.
"""

from __future__ import annotations

import functools
import re
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from .._validation import (
    as_exemplar,
    check_memory,
    check_output_shape,
    human_bytes,
    normalize_rng,
)
from ..errors import InputError
from ..ops.canvas import default_output_shape
from ..ops.linalg import fixed_order
from ..ops.progress import Progress
from ._deprecation import rename_deprecated, warn_deprecated
from ._memory import pixel_count, planned_exemplar_shape, shape_dims
from ._params import ParamSpec, read_param_specs

__all__ = ["ParamSpec", "Progress", "RowBand", "SynthesisResult", "TextureSynthesizer"]


@dataclass(frozen=True)
class SynthesisResult:
    """One synthesised texture and, for copy-based methods, where its pixels came from.

    Attributes
    ----------
    image : ndarray of float32, shape (H, W) or (H, W, C)
        Values clipped to [0, 1]; same rank and channels as the exemplar (``C`` is 3, or up
        to :attr:`TextureSynthesizer.max_channels` for a method that synthesises channels
        jointly: ``docs/materials.md``).
    source_map : ndarray of int32, shape (H, W, 2), or None
        Exemplar ``(row, col)`` each output pixel was copied from; ``None`` for methods that
        do not copy pixels.
    diagnostics : dict or None
        What a method measured during the run when asked to (for example
        ``portilla_simoncelli`` with ``record_distance=True``: the statistics distance after
        every iteration); ``None`` otherwise.
    """

    image: np.ndarray
    source_map: np.ndarray | None = None
    diagnostics: dict | None = None


@dataclass(frozen=True)
class RowBand:
    """Consecutive full-width rows of an output, as :meth:`TextureSynthesizer.sample_rows` yields them.

    Attributes
    ----------
    top : int
        Index of the band's first row in the output.
    image : ndarray of float32, shape (k, W) or (k, W, 3)
        The rows, as :meth:`TextureSynthesizer.sample` returns them.
    source_map : ndarray of int32, shape (k, W, 2), or None
        Their exemplar positions (copy-based methods).
    """

    top: int
    image: np.ndarray
    source_map: np.ndarray | None = None


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
    #: the most channels ``fit`` takes: 3 (grey or colour; an alpha channel is dropped), or
    #: more for a method whose statistics treat any number of channels jointly, so that a
    #: material stack or an RGBA exemplar is synthesised as one image (``docs/materials.md``)
    max_channels: ClassVar[int] = 3
    #: whether every output pixel equals the pixel its source map names in :attr:`source_image`
    source_map_exact: ClassVar[bool] = True
    #: rough working memory per pixel and channel, in bytes: the default of
    #: :meth:`memory_terms` for methods that do not model their memory in more detail
    bytes_per_pixel: ClassVar[float] = 256.0
    #: factor on the sum of :meth:`memory_terms` for the arrays too small to be modelled one
    #: by one and the allocator's slack; 1 MiB is added for small objects (``docs/memory.md``)
    memory_margin: ClassVar[float] = 1.25
    #: the same factor for a streamed run (:meth:`streaming_memory_terms`): its terms are small
    #: and the allocator's slack around them is not calibrated (``docs/memory.md``)
    streaming_memory_margin: ClassVar[float] = 1.25
    #: parameters that change what ``fit`` learns, for methods whose saved models hold the
    #: learned arrays (:meth:`fitted_arrays`): :func:`texsyn.load` refuses new values for them
    learned_params: ClassVar[tuple[str, ...]] = ()
    #: the names of :meth:`fitted_arrays` (``None``: the method stores none)
    fitted_names: ClassVar[re.Pattern[str] | None] = None
    #: whether :meth:`sample_rows` holds only a working window of the output (the method
    #: defines ``_sample_rows``); otherwise it yields the whole image as one band
    streams_rows: ClassVar[bool] = False

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if "__init__" in cls.__dict__:
            init = cls.__dict__["__init__"]

            @functools.wraps(init)
            def __init__(self, *args: Any, **params: Any) -> None:
                if type(self).__init__ is __init__:  # the outermost: warn once, at the user's line
                    params = type(self).canonical_params(params)
                    for message in type(self).deprecated_values(params):
                        warn_deprecated(message)
                init(self, *args, **params)

            cls.__init__ = __init__  # type: ignore[method-assign]

    @classmethod
    def canonical_params(cls, params: dict[str, Any], *, stacklevel: int | None = None) -> dict[str, Any]:
        """``params`` with deprecated names replaced by their new ones (a warning each).

        ``stacklevel`` counts from the caller (1); ``None`` names the first frame outside
        texsyn, the user's (:func:`~texsyn.methods._deprecation.user_stacklevel`).

        Raises
        ------
        InputError
            When a parameter is given under both its old and its new name.
        """
        level = None if stacklevel is None else stacklevel + 1
        return rename_deprecated(params, cls.deprecated_params, cls.name, level)

    @classmethod
    def deprecated_values(cls, params: dict[str, Any]) -> list[str]:
        """Warnings for deprecated values in ``params``, given at construction (none by default)."""
        return []

    # ------------------------------------------------------------------ parameters
    @classmethod
    def param_specs(cls) -> dict[str, ParamSpec]:
        """The hyperparameters, read from the ``__init__`` signature and docstring."""
        return read_param_specs(cls.__init__, cls.__doc__)

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

    def streaming_memory_terms(
        self, exemplar_shape: tuple[int, ...], output_shape: tuple[int, int]
    ) -> dict[str, float]:
        """Named parts of the peak memory of :meth:`sample_rows`, in bytes (``docs/memory.md``).

        For a method that streams (:attr:`streams_rows`) the hook to override: its working
        window instead of the whole canvas; otherwise :meth:`memory_terms`, since the whole
        image is made before it is yielded.
        """
        return self.memory_terms(exemplar_shape, output_shape)

    def estimate_memory(
        self,
        exemplar_shape: tuple[int, ...],
        output_shape: tuple[int, int] | None = None,
        *,
        streaming: bool = False,
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
        streaming : bool
            Estimate :meth:`sample_rows` (:meth:`streaming_memory_terms`) rather than
            :meth:`sample`.

        Returns
        -------
        int
        """
        self._check_params()
        out = None if output_shape is None else (int(output_shape[0]), int(output_shape[1]))
        streamed = streaming and out is not None and bool(self.streams_rows)
        if streamed and out is not None:
            terms = self.streaming_memory_terms(tuple(exemplar_shape), out)
        else:
            terms = self.memory_terms(tuple(exemplar_shape), out)
        return int(np.ceil(self._memory_total(terms, streaming=streamed)))

    def check_memory_for(
        self,
        exemplar_shape: tuple[int, ...],
        output_shape: tuple[int, int] | None = None,
        *,
        streaming: bool = False,
    ) -> None:
        """Refuse, before any data is read, work that would exceed ``TEXSYN_MEMORY_LIMIT``.

        For front doors that know the shapes first (the command line reads an image file's
        header before its pixels): checks fitting an exemplar of ``exemplar_shape`` and, when
        ``output_shape`` is given, sampling that size from it.

        With ``streaming``, the sampling is :meth:`sample_rows`'s (:meth:`streaming_memory_terms`).

        Raises
        ------
        MemoryLimitError
            The estimate (:meth:`estimate_memory`) exceeds the limit.
        """
        self._check_params()
        self._check_memory(tuple(exemplar_shape))
        if output_shape is not None:
            out = (int(output_shape[0]), int(output_shape[1]))
            streamed = streaming and bool(self.streams_rows)
            terms = self.streaming_memory_terms(tuple(exemplar_shape), out) if streamed else None
            self._check_memory(tuple(exemplar_shape), out, terms=terms, streaming=streamed)

    def _memory_total(self, terms: dict[str, float], *, streaming: bool = False) -> float:
        """:attr:`memory_margin` (:attr:`streaming_memory_margin` for a streamed run) times
        the terms, plus 1 MiB of small arrays and objects."""
        margin = self.streaming_memory_margin if streaming else self.memory_margin
        return margin * float(sum(terms.values())) + 2.0**20

    def _check_memory(
        self,
        exemplar_shape: tuple[int, ...],
        output_shape: tuple[int, int] | None = None,
        *,
        task: str | None = None,
        advice: str | None = None,
        terms: dict[str, float] | None = None,
        streaming: bool = False,
    ) -> None:
        """Raise :class:`~texsyn.errors.MemoryLimitError` when the estimate exceeds the limit."""
        if terms is None:
            terms = self.memory_terms(tuple(exemplar_shape), output_shape)
        need = self._memory_total(terms, streaming=streaming)
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

    # ------------------------------------------------------------------ saved models
    def fitted_arrays(self) -> dict[str, np.ndarray]:
        """What ``fit`` learned that :func:`texsyn.save` stores besides the exemplar (``docs/persistence.md``).

        Empty by default: ``fit`` is deterministic, so :func:`texsyn.load` fits the saved exemplar
        again, bit for bit. A method whose fit is expensive returns its model's arrays (``sparse``).
        """
        self._require_fitted()
        return {}

    def restore_fitted(self, exemplar: np.ndarray, arrays: dict[str, np.ndarray]) -> TextureSynthesizer:
        """Make this unfitted instance the model saved with ``exemplar`` and ``arrays``; ``self``.

        The default fits ``exemplar`` again; a method that overrides :meth:`fitted_arrays`
        rebuilds its model from ``arrays`` (:class:`~texsyn.errors.InputError` if they do not fit).
        """
        self.check_fitted_names(list(arrays))
        return self.fit(exemplar)

    def check_fitted_names(self, names: list[str]) -> None:
        """Refuse array names :meth:`fitted_arrays` never writes (:attr:`fitted_names`), before they are read."""
        unknown = sorted(n for n in names if self.fitted_names is None or not self.fitted_names.fullmatch(n))
        if unknown:
            listed = ", ".join(repr(n)[:60] for n in unknown[:3])
            raise InputError(f"a saved model of method {self.name!r} holds no arrays named {listed}")

    # ------------------------------------------------------------------ fit / sample
    def min_exemplar_size(self) -> tuple[int, str]:
        """Smallest exemplar side this configuration accepts, and why."""
        return 2, "at least 2x2 pixels"

    @fixed_order
    def fit(self, exemplar: np.ndarray) -> TextureSynthesizer:
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
        planned = planned_exemplar_shape(exemplar)
        if planned is not None:  # before the (float64) conversion of a large array
            self._check_memory(planned)
        ex = as_exemplar(exemplar, max_channels=self.max_channels)
        side, why = self.min_exemplar_size()
        if min(ex.shape[:2]) < side:
            raise InputError(
                f"exemplar of {ex.shape[1]}x{ex.shape[0]} pixels is too small for method {self.name!r}: {why}"
            )
        if planned != ex.shape:
            self._check_memory(ex.shape)
        self.exemplar_ = ex
        self._fit(ex)
        return self

    def _fit(self, exemplar: np.ndarray) -> None:  # pragma: no cover - trivial default
        pass

    @property
    def source_image(self) -> np.ndarray:
        """The image whose positions a source map names: the fitted exemplar, or the image a
        method copies from in its place (``patch_wavelet``: the exemplar's periodic component)."""
        return self._require_fitted()

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
        tileable: bool = False,
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
        tileable : bool
            Make the output wrap seamlessly in both directions (:attr:`tiling` says how;
            ``docs/materials.md``, "Tileable outputs").

        Returns
        -------
        ndarray of float32, values clipped to [0, 1], rank and channels of the exemplar.

        Raises
        ------
        MemoryLimitError
            Before any work, when the estimate exceeds the limit (``docs/memory.md``).

        Examples
        --------
        >>> import texsyn
        >>> model = texsyn.make_method("quilting", patch_size=12).fit(texsyn.data.exemplar("brick", size=48))
        >>> stages = []
        >>> texture = model.sample((64, 80), rng=1, callback=lambda p: stages.append(p.stage))
        >>> texture.shape, stages[-1]
        ((64, 80), 'blocks')
        >>> bool((model.sample((64, 80), rng=1) == texture).all())  # the fitted model is unchanged
        True
        """
        return self.sample_with_map(shape, rng=rng, callback=callback, tileable=tileable).image

    @fixed_order
    def sample_with_map(
        self,
        shape: tuple[int, int] | None = None,
        *,
        rng: None | int | np.random.Generator = None,
        callback: Callable[[Progress], None] | None = None,
        tileable: bool = False,
    ) -> SynthesisResult:
        """Like :meth:`sample`, but also return the source map of copy-based methods."""
        ex = self._require_fitted()
        out_shape = check_output_shape(default_output_shape(ex.shape) if shape is None else shape)
        self._check_memory(ex.shape, out_shape)
        generator = normalize_rng(rng)
        tiling = self.tiling_for(out_shape) if tileable else None
        if tiling == "torus":
            sampled = self._sample_torus(out_shape, generator, callback)
        else:
            sampled = self._sample(out_shape, generator, callback)
        image, source = sampled[0], sampled[1]
        diagnostics = sampled[2] if len(sampled) > 2 else None
        if tiling == "seam band":  # methods._tiling
            from ._tiling import quilted_seam_band

            image, source = quilted_seam_band(self._as_output(image), source, self.source_image, generator)
        result = self._as_output(image)
        if source is not None:
            source = np.asarray(source, dtype=np.int32)
        return SynthesisResult(image=result, source_map=source, diagnostics=diagnostics)

    @fixed_order
    def sample_rows(
        self,
        shape: tuple[int, int] | None = None,
        *,
        rng: None | int | np.random.Generator = None,
        callback: Callable[[Progress], None] | None = None,
    ) -> Iterator[RowBand]:
        """Like :meth:`sample_with_map`, as bands of rows from top to bottom.

        A method that synthesises in raster order (:attr:`streams_rows`: quilting) holds
        only a working window of the output and yields its rows as they are finished, so
        that a writer can stream them to a file and any size fits in memory
        (``docs/performance.md``, "Any size in bounded memory"); the others yield the whole
        image as one band. The bands put together are :meth:`sample_with_map`'s result for
        the same ``rng``, byte for byte.

        Parameters
        ----------
        shape, rng, callback
            As in :meth:`sample`.

        Yields
        ------
        RowBand

        Raises
        ------
        MemoryLimitError
            Before any work, when the estimate (of the working window, for a method that
            streams) exceeds the limit (``docs/memory.md``).

        Examples
        --------
        >>> import texsyn
        >>> model = texsyn.make_method("quilting", patch_size=12).fit(texsyn.data.exemplar("brick", size=48))
        >>> bands = list(model.sample_rows((64, 80), rng=1))
        >>> [(band.top, band.image.shape[0]) for band in bands][:2]
        [(0, 10), (10, 10)]
        >>> bool((np.concatenate([b.image for b in bands]) == model.sample((64, 80), rng=1)).all())
        True
        """
        if not self.streams_rows:
            result = self.sample_with_map(shape, rng=rng, callback=callback)
            yield RowBand(0, result.image, result.source_map)
            return
        ex = self._require_fitted()
        out_shape = check_output_shape(default_output_shape(ex.shape) if shape is None else shape)
        self._check_memory(ex.shape, out_shape, terms=self.streaming_memory_terms(ex.shape, out_shape))
        top = 0
        for image, source in self._sample_rows(out_shape, normalize_rng(rng), callback):
            rows = self._as_output(image)
            yield RowBand(top, rows, None if source is None else np.asarray(source, dtype=np.int32))
            top += rows.shape[0]

    def _sample_rows(
        self,
        shape: tuple[int, int],
        rng: np.random.Generator,
        callback: Callable[[Progress], None] | None,
    ) -> Iterator[tuple[np.ndarray, np.ndarray | None]]:
        """The method's synthesis as ``(rows, source_rows)`` bands, top to bottom (:attr:`streams_rows`)."""
        raise NotImplementedError  # pragma: no cover - only methods that stream define it

    def tiling_for(self, shape: tuple[int, int]) -> str:
        """How ``tileable=True`` makes an output of ``shape`` wrap (``docs/tiling.md``).

        Returns
        -------
        str
            ``"periodic"``: the method's canvas is periodic by construction
            (:meth:`periodic_for`), the output is the plain one; ``"torus"``: the method
            searches and stitches on a torus itself, with wrap-around neighbourhoods and
            seams (:meth:`torus_for`); ``"seam band"``: the output is drawn as usual and a
            band across each wrap is quilted again from the exemplar
            (:func:`texsyn.methods._tiling.quilted_seam_band`).
        """
        if self.periodic_for(shape):
            return "periodic"
        if self.torus_for(shape):
            return "torus"
        return "seam band"

    def torus_for(self, shape: tuple[int, int]) -> bool:
        """Whether the method can synthesise an output of ``shape`` on a torus itself
        (:meth:`_sample_torus`): its neighbourhoods and seams wrap around the output's edges."""
        return False

    def _sample_torus(
        self,
        shape: tuple[int, int],
        rng: np.random.Generator,
        callback: Callable[[Progress], None] | None,
    ) -> tuple[np.ndarray, np.ndarray | None] | tuple[np.ndarray, np.ndarray | None, dict]:
        """:meth:`_sample` on a torus: the output wraps in both directions (:meth:`torus_for`)."""
        raise NotImplementedError  # pragma: no cover - only methods whose torus_for is true

    def periodic_for(self, shape: tuple[int, int]) -> bool:
        """Whether an output of ``shape`` wraps around by construction.

        ``tileable=True`` then samples as usual; otherwise a band across each wrap of the
        output is quilted again from the exemplar (:func:`texsyn.methods._tiling.quilted_seam_band`;
        ``docs/tiling.md``).
        The spectral methods whose working canvas is the output itself say so.
        """
        return False

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
    ) -> tuple[np.ndarray, np.ndarray | None] | tuple[np.ndarray, np.ndarray | None, dict]:
        """The method's synthesis: ``(image, source_map)``, or with a third item, its diagnostics."""
        raise NotImplementedError  # pragma: no cover - abstract
