"""What the grouplet method learns from an exemplar (Peyré 2008, section 3.1).

The model has two layers: a geometric layer, the exemplar's direction field ``Gamma_0``
(section 2.1), and a coefficient layer, the sorted values of every band of the exemplar's
wavelet-grouplet coefficients and of its pixels (the marginals ``D_0``). The model is built
once by :meth:`GroupletModel.from_exemplar` and never changed afterwards: everything that
depends on the output size (the histogram targets of section 3.2, eq. 4) is computed per call
by :meth:`GroupletModel.targets` and held by the caller (``docs/methods/grouplets.md``).
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any, cast

import numpy as np

from ..ops import luma, match_sorted_rows, periodic_smooth_decomposition
from ..ops.color import ColorPCA, ColourSpace, colour_space
from ..ops.flow import association_fields, orient_field, structure_tensor_orientation, tiled_associations
from ..ops.histogram import hist_target_rows
from ..ops.progress import Reporter
from ..transforms.grouplets import WaveletGroupletTransform

__all__ = ["ASSOCIATION_STEP", "GroupletModel", "HistogramTargets", "ProjectionBuffers"]

#: integration step (pixels) of the association fields of the exemplar and of static syntheses
ASSOCIATION_STEP = 0.25


@dataclass(frozen=True)
class HistogramTargets:
    """Sorted target values of every constraint of the model for an output of ``n`` pixels.

    The projection of eq. 4 (Peyré 2008, section 3.2) needs as many target values as the
    output has coefficients; when the exemplar and the output differ in size they are the
    quantile transport of the exemplar's values (:func:`texsyn.ops.hist_target`).

    Attributes
    ----------
    bands : ndarray, shape (B, n)
        One row per wavelet-grouplet band ``(j, l, channel)``, ascending.
    pixels : ndarray, shape (C, n)
        One row per channel, ascending.
    """

    bands: np.ndarray
    pixels: np.ndarray

    def __iter__(self) -> Iterator[np.ndarray]:
        """Deprecated: round 1's ``targets(n)`` was the tuple ``(bands, pixels)``."""
        _warn_targets_tuple()
        return iter((self.bands, self.pixels))

    def __getitem__(self, index: int) -> np.ndarray:
        """Deprecated: round 1's ``targets(n)`` was the tuple ``(bands, pixels)``."""
        _warn_targets_tuple()
        return (self.bands, self.pixels)[index]


@dataclass(frozen=True)
class ProjectionBuffers:
    """Arrays that every pass of Table 1 writes, allocated once per synthesis and reused.

    A 256x256 colour pass writes about 100 MB of coefficients, sort keys and scan residuals;
    fresh arrays would be fresh pages, which the kernel faults in one by one (about a third
    of the time of a pass, ``docs/methods/grouplets.md``, "Performance"). The buffers hold
    no state from one pass to the next: the results are the same bytes.

    Attributes
    ----------
    coefficients : ndarray of float64, shape (L+1, J+1, C, H, W)
        The analysis, then (in place) the matched coefficients.
    keys : ndarray of uint64, shape ((L+1)(J+1)C, H*W)
        The sort keys of the bands (:func:`texsyn.ops.match_sorted_rows`).
    work : ndarray of float64
        The transform's scratch space (:meth:`WaveletGroupletTransform.work_buffer`).
    """

    coefficients: np.ndarray
    keys: np.ndarray
    work: np.ndarray


def _warn_targets_tuple() -> None:
    warnings.warn(
        "GroupletModel.targets(n) returns a HistogramTargets; using it as a (bands, pixels) tuple "
        "is deprecated: use .bands and .pixels",
        DeprecationWarning,
        stacklevel=3,
    )


#: keywords of round 1's ``GroupletModel(exemplar, ...)``, now :meth:`GroupletModel.from_exemplar`
_ROUND1_KEYWORDS = frozenset({"exemplar", "levels", "grouplet_levels", "sigma", "presmooth", "colour"})


class _LearnsFromExemplar(type):
    """Metaclass of :class:`GroupletModel`: the round-1 call form, deprecated.

    ``GroupletModel(exemplar, levels=..., ...)`` learned the model in round 1; it now warns
    and returns :meth:`GroupletModel.from_exemplar`'s model. Every other call (the fields, as
    :meth:`from_exemplar`, :func:`dataclasses.replace` and unpickling make it) is the frozen
    dataclass's own constructor. The forms cannot be confused: the dataclass needs at least
    ``flow``, ``coherence``, ``band_values`` and ``pixel_values``, which round 1 never took.
    """

    def __call__(cls, *args: Any, **kwargs: Any) -> Any:
        positional_exemplar = len(args) == 1 and "exemplar" not in kwargs
        keyword_exemplar = not args and "exemplar" in kwargs
        if (positional_exemplar or keyword_exemplar) and kwargs.keys() <= _ROUND1_KEYWORDS:
            warnings.warn(
                "GroupletModel(exemplar, ...) is deprecated; use GroupletModel.from_exemplar(exemplar, ...)",
                DeprecationWarning,
                stacklevel=2,
            )
            exemplar = args[0] if args else kwargs.pop("exemplar")
            return cls.from_exemplar(exemplar, **kwargs)  # type: ignore[attr-defined]
        return super().__call__(*args, **kwargs)


@dataclass(frozen=True, eq=False)
class GroupletModel(metaclass=_LearnsFromExemplar):
    """The statistics of Peyré's grouplet model, learned from an exemplar (paper section 3.1).

    Build it with :meth:`from_exemplar`; its arrays are read-only. Round 1's
    ``GroupletModel(exemplar, levels=..., ...)`` still works, deprecated.

    Attributes
    ----------
    flow : ndarray (H, W, 2)
        Learned direction field ``Gamma_0`` (unit vectors, signs optimised).
    coherence : ndarray (H, W)
        Anisotropy of the structure tensor, in [0, 1].
    band_values : ndarray (J+1, L+1, C, H*W)
        Sorted wavelet-grouplet coefficients of the exemplar's periodic component.
    pixel_values : ndarray (C, H*W)
        Sorted pixel values of the exemplar's periodic component (principal-axis coordinates
        for colour).
    levels, grouplet_levels : int
        ``J`` pyramid detail bands and ``L`` grouplet scales.
    space : ColourSpace
        The colour coordinates synthesised (:func:`texsyn.ops.color.colour_space`): the
        principal axes of a colour exemplar, or its luma.
    associations : ndarray of int64 (L, H*W), optional
        The association fields of ``flow`` (:func:`texsyn.ops.flow.association_fields`, step
        0.25), which an output tiling the exemplar's field exactly reuses
        (:meth:`tiled_transform`). ``None`` in models made without them (round 1's pickles).
    """

    flow: np.ndarray
    coherence: np.ndarray
    band_values: np.ndarray
    pixel_values: np.ndarray
    levels: int
    grouplet_levels: int
    space: ColourSpace = ColourSpace("grey", 1)
    associations: np.ndarray | None = None

    @property
    def pca(self) -> ColorPCA | None:
        """The principal colour axes, ``None`` when the model is grey."""
        return self.space.pca

    def __post_init__(self) -> None:
        for name in ("flow", "coherence", "band_values", "pixel_values", "associations"):
            if name == "associations" and self.associations is None:
                continue
            array = np.asarray(getattr(self, name))
            array.setflags(write=False)
            object.__setattr__(self, name, array)

    def __setstate__(self, state: dict) -> None:
        """Unpickling (a model shipped to a batch worker) keeps the arrays read-only."""
        self.__dict__.update(state)
        self.__post_init__()

    @classmethod
    def from_exemplar(
        cls,
        exemplar: np.ndarray,
        *,
        levels: int = 3,
        grouplet_levels: int = 4,
        sigma: float = 5.0,
        presmooth: float = 1.0,
        colour: str = "pca",
    ) -> GroupletModel:
        """Learn both layers from an exemplar (section 3.1).

        Parameters
        ----------
        exemplar : ndarray, shape (H, W) or (H, W, 3)
        levels, grouplet_levels : int
            ``J`` pyramid detail bands and ``L`` grouplet scales.
        sigma, presmooth : float
            Structure-tensor smoothing and gradient pre-smoothing (pixels).
        colour : {'pca', 'grey'}
            Colour exemplars: synthesise the three principal colour axes with one shared
            geometry, or convert to grey (``docs/methods/grouplets.md``, "Deviations").

        Examples
        --------
        >>> import numpy as np
        >>> stripes = 0.5 + 0.5 * np.sin(np.arange(16)[None, :] * np.ones((16, 1)))
        >>> model = GroupletModel.from_exemplar(stripes, levels=2, grouplet_levels=2)
        >>> model.band_values.shape, model.pixel_values.shape
        ((3, 3, 1, 256), (1, 256))
        >>> model.flow.flags.writeable
        False
        """
        img = np.asarray(exemplar, dtype=np.float64)  # (H, W) or (H, W, 3)
        # one periodic component (Moisan) serves the geometry and all the statistics, pixels
        # included: the output is periodic, and its pixel histogram then carries the energy
        # its bands carry (the original pixels' would add the border jumps' energy, or remove
        # it: +-10 % on every band of a 256x256 synthesis). The decomposition is linear and
        # keeps the mean, so it commutes with luma and colour PCA.
        periodic_img = periodic_smooth_decomposition(img)[0]
        space = colour_space(colour, img)
        periodic = space.forward(periodic_img)
        orientation, coherence = structure_tensor_orientation(
            luma(periodic_img), sigma=sigma, presmooth=presmooth
        )
        flow = orient_field(orientation)
        associations = association_fields(flow, int(grouplet_levels), step=ASSOCIATION_STEP)
        transform = _normalized_transform(associations, flow.shape[:2], int(levels))
        coefficients = transform.forward(periodic)  # (J+1, L+1, C, H, W)
        b = coefficients.reshape(coefficients.shape[:3] + (-1,))
        return cls(
            flow=flow,
            coherence=coherence,
            band_values=np.sort(b, axis=-1),
            pixel_values=np.sort(periodic.reshape(-1, periodic.shape[2]).T, axis=-1),
            levels=int(levels),
            grouplet_levels=int(grouplet_levels),
            space=space,
            associations=associations,
        )

    @property
    def shape(self) -> tuple[int, int]:
        """``(H, W)`` of the exemplar."""
        return (int(self.flow.shape[0]), int(self.flow.shape[1]))

    @property
    def channels(self) -> int:
        """Channels synthesised: 3 principal colour axes, or 1 grey channel."""
        return self.pixel_values.shape[0]

    def transform(self, flow: np.ndarray, *, step: float = ASSOCIATION_STEP) -> WaveletGroupletTransform:
        """The wavelet-grouplet transform along ``flow`` (raw vectors, any size; section 2.3).

        ``step`` is the integration step of the association fields in pixels
        (:func:`texsyn.ops.flow.association_fields`).
        """
        flow = np.asarray(flow, dtype=np.float64)
        associations = association_fields(flow, self.grouplet_levels, step=step)
        return _normalized_transform(associations, flow.shape[:2], self.levels)

    def tiled_transform(self, shape: tuple[int, int]) -> WaveletGroupletTransform | None:
        """The transform along the exemplar's flow tiled exactly to ``shape``
        (:func:`texsyn.ops.flow.periodic_tiling` of a multiple of its size), from the
        exemplar's association fields moved by whole tiles instead of integrated again
        (:func:`texsyn.ops.flow.tiled_associations`); ``None`` where that does not apply
        (then :meth:`transform` of the tiling)."""
        if self.associations is None:
            return None
        associations = tiled_associations(self.associations, self.shape, shape)
        if associations is None:
            return None
        return _normalized_transform(associations, (int(shape[0]), int(shape[1])), self.levels)

    def targets(self, n: int) -> HistogramTargets:
        """Sorted target values of every band and channel for ``n`` pixels (computed, not kept)."""
        bands = self.band_values.reshape(-1, self.band_values.shape[-1])
        return HistogramTargets(hist_target_rows(n, bands), hist_target_rows(n, self.pixel_values))

    def noise(self, shape: tuple[int, int], rng: np.random.Generator) -> np.ndarray:
        """White noise ``(H, W, C)`` with the exemplar's mean and deviation per channel."""
        mean = self.pixel_values.mean(axis=1)
        std = self.pixel_values.std(axis=1)
        return mean + std * rng.standard_normal(tuple(shape) + (self.channels,))

    def match_bands(self, coefficients: np.ndarray, targets: HistogramTargets | None = None) -> np.ndarray:
        """Give every band of ``(J+1, L+1, C, H, W)`` coefficients the exemplar's histogram.

        Table 1, step 3 (eq. 4). ``targets`` from :meth:`targets` (computed here when omitted).
        """
        n = coefficients.shape[-1] * coefficients.shape[-2]
        bands = (self.targets(n) if targets is None else targets).bands
        rows = coefficients.reshape(-1, n)
        return match_sorted_rows(rows, bands).reshape(coefficients.shape)

    def match_pixels(self, image: np.ndarray, targets: HistogramTargets | None = None) -> np.ndarray:
        """Give every channel of an ``(H, W, C)`` image the exemplar's pixel histogram (Table 1, step 5)."""
        n = image.shape[0] * image.shape[1]
        pixels = (self.targets(n) if targets is None else targets).pixels
        return match_sorted_rows(image.reshape(n, self.channels).T, pixels).T.reshape(image.shape)

    def buffers(self, transform: WaveletGroupletTransform) -> ProjectionBuffers:
        """The arrays :meth:`project_once` reuses from one pass to the next with ``transform``."""
        levels = transform.grouplets.levels + 1
        bands = transform.pyramid.levels + 1
        shape = (levels, bands, self.channels) + transform.shape
        return ProjectionBuffers(
            coefficients=np.empty(shape),
            keys=np.empty((levels * bands * self.channels, transform.size), dtype=np.uint64),
            work=transform.work_buffer(self.channels),
        )

    def project_once(
        self,
        image: np.ndarray,
        transform: WaveletGroupletTransform,
        targets: HistogramTargets,
        buffers: ProjectionBuffers | None = None,
    ) -> np.ndarray:
        """One pass of Table 1, steps 2-5: analyse, match the bands, synthesise, match the pixels.

        Step 6 of the paper goes back to step 3; the coefficients must be recomputed from the
        new image, so a pass starts again from the analysis (step 2). The bands are matched
        in the transform's own layout (:meth:`WaveletGroupletTransform.analyse`), each to its
        row of ``targets.bands``, in place, without reordering copies. ``buffers`` (from
        :meth:`buffers`) are reused by every pass; the result is the same without them.
        """
        out, keys, work = (
            (None, None, None) if buffers is None else (buffers.coefficients, buffers.keys, buffers.work)
        )
        coefficients = transform.analyse(image, out=out, work=work)  # (L+1, J+1, C, H, W)
        levels, bands, channels = coefficients.shape[:3]
        # row (l, j, c) of the layout is row (j, l, c) of the targets
        order = np.arange(bands * levels * channels).reshape(bands, levels, channels)
        rows = np.transpose(order, (1, 0, 2)).ravel()
        n = coefficients.shape[-1] * coefficients.shape[-2]
        flat = coefficients.reshape(-1, n)
        match_sorted_rows(flat, targets.bands, rows=rows, out=flat, keys=keys)
        return self.match_pixels(transform.synthesise(coefficients, work=work), targets)

    def to_image(self, channels: np.ndarray) -> np.ndarray:
        """``(H, W, C)`` model channels (principal-axis coordinates) to an ``(H, W[, 3])`` image."""
        return self.space.inverse(channels)

    def project(
        self,
        image: np.ndarray,
        transform: WaveletGroupletTransform,
        iterations: int,
        callback: Callable[[int, np.ndarray], None] | None = None,
    ) -> np.ndarray:
        """Deprecated: use :func:`texsyn.drivers.alternating.alternate_projections` with :meth:`project_once`.

        Round 1's alternating projections onto the model (Table 1, steps 2-6), kept with a
        :class:`DeprecationWarning`: ``iterations`` passes of :meth:`project_once` with the
        targets of the image's size; ``callback(k, channels)`` after pass ``k``. The driver
        is imported when this is called, never when ``texsyn.models`` is imported.
        """
        warnings.warn(
            "GroupletModel.project is deprecated; use texsyn.drivers.alternating.alternate_projections "
            "with GroupletModel.project_once",
            DeprecationWarning,
            stacklevel=2,
        )
        from ..drivers.alternating import alternate_projections

        targets = self.targets(image.shape[0] * image.shape[1])
        reporter = None
        if callback is not None:
            legacy = callback
            reporter = Reporter(
                lambda record: legacy(record.done, cast(np.ndarray, record.image)), "iteration", iterations
            )
        return alternate_projections(
            image,
            lambda f, _k: self.project_once(f, transform, targets),
            iterations,
            reporter=reporter,
            preview=lambda f: f,
        )


def _normalized_transform(
    associations: np.ndarray, shape: tuple[int, int], levels: int
) -> WaveletGroupletTransform:
    """The wavelet-grouplet frame of association fields, with normalised coefficients
    (``docs/methods/grouplets.md``, "Deviations")."""
    return WaveletGroupletTransform(associations, shape, levels, normalized=True)
