"""Constrained sparse texture synthesis (Tartavel, Gousseau, Peyré 2013).

A dictionary of patch atoms is learned on the exemplar (K-SVD, S-sparse codes) together
with how often each atom is used (:mod:`texsyn.models.sparse`). Synthesis minimises, by
block-coordinate descent from white noise, the energy (3) of the paper: sparse coding of the
patches of the image on a periodic grid, each atom used at most as often as in the exemplar
(constrained matching pursuit), the Wasserstein distance to the exemplar's histogram, and a
low-pass term; the linear patch averaging is replaced by graph-cut stitching, and a
coarse-to-fine loop over ``J`` scales gives large-scale coherence. The paper's steps, the
functions that implement them and our resolutions of its open points are in
``docs/methods/sparse.md``.

Why this module is long: besides Algorithm 1 (with its convergence test and energy curve)
the class carries the five ablation modes of Fig. 4, the memory model and the persistence of
texsyn 0.1's in-memory state (``fitted_state``), which must stay with the class it rebuilds.

References
----------
G. Tartavel, Y. Gousseau, G. Peyré, "Constrained sparse texture synthesis", SSVM 2013.
"""

from __future__ import annotations

import json
import time
import warnings
from typing import Annotated

import numpy as np

from .._validation import OneOf, Range
from ..errors import InputError
from ..models.sparse import ARRAY_NAME, SparseScale, learn_sparse_model, sparse_model_from_arrays
from ..ops.canvas import crop_to_output, padded_canvas
from ..ops.graphcut import graphcut_reassemble
from ..ops.histogram import HistogramMatcher
from ..ops.linalg import matmul
from ..ops.patches import average_patches, extract_patches
from ..ops.progress import Reporter
from ..ops.sparse import (
    SpectrumProjector,
    box_power,
    constrained_matching_pursuit,
    image_energy,
    image_update,
    lowpass_towards,
    upsample_bicubic,
)
from ._base import TextureSynthesizer
from ._memory import output_bytes, pixel_count, shape_dims, sparse_fit_bytes

__all__ = ["ConstrainedSparse", "MODES", "image_energy", "image_update", "upsample_bicubic"]

#: default convergence tolerance: relative decrease of the energy (3) below its best value
TOLERANCE = 5e-3
#: outer iterations in a row without that decrease after which a scale has converged
PATIENCE = 3
#: the step-by-step study of the paper's Fig. 4, each mode adding one ingredient
MODES = ("basic", "frequency", "graphcut", "multiscale", "full")
FORMAT_VERSION = 1  # of the deprecated in-memory state (fitted_state, texsyn 0.1)
#: parameters that change what ``fit`` learns (a loaded dictionary cannot change them)
LEARNED: tuple[str, ...] = (
    "patch_size",
    "step",
    "n_scales",
    "sparsity",
    "n_atoms",
    "ksvd_iterations",
    "ksvd_training",
    "fit_rng",
)


class ConstrainedSparse(TextureSynthesizer):
    """Constrained sparse synthesis: sparse patch coding with atom-frequency constraints.

    ``fit`` learns, per scale, a dictionary of ``n_atoms`` unit-norm atoms (K-SVD with exact
    ``sparsity``-sparse OMP codes) and how many exemplar patches use each atom.
    ``sample`` starts from white noise and alternates the constrained matching pursuit of
    the patches on a periodic grid of step ``step`` and gradient steps on the image; the
    ``mode`` switches reproduce the paper's step-by-step study (Fig. 4).

    Parameters
    ----------
    patch_size : int
        Patch width ``tau``.
    step : int
        Grid step ``Delta``; it must divide ``patch_size``, and ``2 step >= patch_size`` for
        the graph-cut modes.
    n_scales : int
        Number of scales ``J`` of the modes 'multiscale' and 'full'.
    sparsity : int
        Atoms per patch ``S``.
    n_atoms : int
        Dictionary size ``N`` (reduced at scales with few exemplar patches).
    alpha : float
        Weight of the histogram (Wasserstein) term.
    beta : float
        Weight of the low-pass term (mode 'full' only).
    n_outer : int
        Outer iterations (coefficient update + image update) per scale.
    n_inner : int
        Gradient steps per image update.
    mode : str
        'basic' (sparse coding and histogram, Peyre 2009), 'frequency' (+ atom frequency
        constraint), 'graphcut' (+ graph-cut reconstruction), 'multiscale' (+ scales),
        'full' (+ low-pass term, the complete procedure).
    lowpass_ref : str
        Reference of the low-pass term: 'spectrum' (the output projected on the exemplar's
        Fourier modulus, :class:`texsyn.ops.sparse.SpectrumProjector`: translation invariant,
        keeps the exemplar's large-scale energy), 'mean' (the exemplar's mean colour, which
        flattens large-scale variation; texsyn 0.2's default) or 'aligned' (the exemplar
        itself; only when the output fits inside it).
    spectrum_weight : float
        With ``lowpass_ref='spectrum'``: the per-frequency weight of the term is
        ``max(|h^|^2, spectrum_weight)``. 0 is the paper's low-pass weighting (the box's
        ``|h^|^2``); the default 1 weights every frequency alike, so the term keeps the
        exemplar's whole Fourier modulus (the spectrum constraint of the authors' JMIV 2015
        sequel; ``docs/methods/sparse.md``, "Low-pass reference", for the measurements).
    final_histogram : bool
        Impose the exemplar's histogram on the returned image.
    final_rounds : int
        With ``lowpass_ref='spectrum'`` in mode 'full': rounds of (low frequencies moved to
        the spectrum projection by the box's ``|h^|``, then the histogram) after the last
        iteration (``docs/methods/sparse.md``, "Final rounds"); the iterations leave the
        local-mean spread up to 20 % above the exemplar's where the codes lack fine detail.
        0 skips them (texsyn 0.2).
    random_offset : bool
        Shift the patch grid by a random offset at every outer iteration.
    ksvd_iterations : int
        K-SVD iterations in fit.
    ksvd_training : int
        Training patches drawn per K-SVD iteration.
    tolerance : float
        Convergence criterion of a scale: stop when the energy (3) has not gone below
        ``(1 - tolerance)`` times its lowest value so far for ``PATIENCE`` (3) outer
        iterations in a row; 0 runs all ``n_outer``. The energy of every outer iteration is
        returned in ``sample_with_map(...).diagnostics``.
    fit_rng : int
        Seed of the randomness of fit (K-SVD initialisation and subsets); ``sample`` takes
        its own ``rng``. Formerly ``random_state`` (deprecated).

    References
    ----------
    G. Tartavel, Y. Gousseau, G. Peyre, "Constrained sparse texture synthesis", SSVM 2013,
    sections 2-4, Algorithms 1-2, eqs. (1)-(12).

    Notes
    -----
    Limitations (paper, Fig. 3): very large-scale structures and noise-like micro-textures
    are poorly reproduced by the sparse model. ``fit`` is the expensive part (K-SVD at every
    scale): :func:`texsyn.save` stores the learned dictionaries, and :func:`texsyn.load`
    may change the sampling parameters of a saved model (``docs/persistence.md``).

    Examples
    --------
    >>> import texsyn
    >>> ex = texsyn.data.exemplar("brick", size=24)
    >>> method = ConstrainedSparse(patch_size=6, step=3, n_scales=1, n_atoms=16,
    ...                            ksvd_iterations=1, n_outer=1, n_inner=1).fit(ex)
    >>> method.model_.scales[0].dictionary.shape
    (36, 16)
    >>> method.sample((12, 12), rng=0).shape
    (12, 12)
    """

    name = "sparse"
    summary = "Constrained sparse synthesis: learned dictionary, atom frequencies, graph cuts"
    reference = "Tartavel, Gousseau, Peyre, SSVM 2013"
    has_source_map = False
    deprecated_params = {"random_state": "fit_rng"}
    learned_params = LEARNED
    fitted_names = ARRAY_NAME

    def __init__(
        self,
        *,
        patch_size: Annotated[int, Range(2, 64)] = 12,
        step: Annotated[int, Range(1, 64)] = 6,
        n_scales: Annotated[int, Range(1, 5)] = 3,
        sparsity: Annotated[int, Range(1, 64)] = 4,
        n_atoms: Annotated[int, Range(2, 4096)] = 384,
        alpha: Annotated[float, Range(0.0, 100.0)] = 1.0,
        beta: Annotated[float, Range(0.0, 100.0)] = 1.0,
        n_outer: Annotated[int, Range(1, 1000)] = 30,
        n_inner: Annotated[int, Range(1, 1000)] = 10,
        mode: Annotated[str, OneOf(MODES)] = "full",
        lowpass_ref: Annotated[str, OneOf(("spectrum", "mean", "aligned"))] = "spectrum",
        spectrum_weight: Annotated[float, Range(0.0, 1.0)] = 1.0,
        final_histogram: bool = True,
        final_rounds: Annotated[int, Range(0, 100)] = 4,
        random_offset: bool = False,
        ksvd_iterations: Annotated[int, Range(1, 1000)] = 20,
        ksvd_training: Annotated[int, Range(10, 10**7)] = 8000,
        tolerance: Annotated[float, Range(0.0, 1.0)] = TOLERANCE,
        fit_rng: Annotated[int, Range(0, 2**32 - 1)] = 0,
    ):
        self.patch_size = patch_size
        self.step = step
        self.n_scales = n_scales
        self.sparsity = sparsity
        self.n_atoms = n_atoms
        self.alpha = alpha
        self.beta = beta
        self.n_outer = n_outer
        self.n_inner = n_inner
        self.mode = mode
        self.lowpass_ref = lowpass_ref
        self.spectrum_weight = spectrum_weight
        self.final_histogram = final_histogram
        self.final_rounds = final_rounds
        self.random_offset = random_offset
        self.ksvd_iterations = ksvd_iterations
        self.ksvd_training = ksvd_training
        self.tolerance = tolerance
        self.fit_rng = fit_rng

    # ---------------------------------------------------------------- configuration
    @property
    def _graphcut(self) -> bool:
        return self.mode in ("graphcut", "multiscale", "full")

    @property
    def _frequency(self) -> bool:
        return self.mode != "basic"

    @property
    def _scales(self) -> int:
        return self.n_scales if self.mode in ("multiscale", "full") else 1

    @property
    def _beta(self) -> float:
        return self.beta if self.mode == "full" else 0.0

    def _check_params(self) -> None:
        super()._check_params()
        tau, step = self.patch_size, self.step
        if step > tau or tau % step:
            raise InputError(f"parameter 'step' of method 'sparse' must divide patch_size={tau}, got {step}")
        if self._graphcut and 2 * step < tau:
            raise InputError(
                f"parameter 'step' of method 'sparse' must be at least patch_size/2={tau / 2:g} "
                f"in mode {self.mode!r} (graph cuts need single overlaps), got {step}"
            )
        if self.n_atoms < self.sparsity + 1:
            raise InputError(
                f"parameter 'n_atoms' of method 'sparse' must exceed sparsity={self.sparsity}, got {self.n_atoms}"
            )

    def min_exemplar_size(self):
        side = self.patch_size * 2 ** (self._scales - 1)
        return (
            side,
            f"patch_size={self.patch_size} with {self._scales} scale(s) needs at least {side}x{side} pixels",
        )

    # ---------------------------------------------------------------- fit
    def _fit(self, exemplar: np.ndarray) -> None:
        model, seconds = learn_sparse_model(
            exemplar,
            n_scales=self._scales,
            patch_size=self.patch_size,
            sparsity=self.sparsity,
            n_atoms=self.n_atoms,
            ksvd_iterations=self.ksvd_iterations,
            ksvd_training=self.ksvd_training,
            seed=self.fit_rng,
        )
        self.model_ = model
        self.fit_seconds_ = seconds

    @property
    def scales_(self) -> tuple[SparseScale, ...]:
        """The learned scales, finest first (``model_.scales``; texsyn 0.1's name)."""
        return self.model_.scales

    # ---------------------------------------------------------------- memory
    def memory_terms(self, exemplar_shape, output_shape=None) -> dict[str, float]:
        """Patches and codes of every exemplar patch (fit); codes of the output patches (sample).

        Fitting holds all ``K`` exemplar patches of the finest scale (``K x tau^2 C`` floats),
        K-SVD's batch OMP on ``ksvd_training`` of them and the constrained matching pursuit
        of all of them (``n_atoms x K`` correlations and codes); sampling holds the codes of
        the output patches or the graph-cut reassembly, and the heap the pursuit leaves
        fragmented (``docs/memory.md``, "Every method at its defaults").
        """
        h, w, c = shape_dims(exemplar_shape)
        dim = self.patch_size * self.patch_size * c
        kept, fit_peak, n = sparse_fit_bytes(
            h, w, c, scales=self._scales, patch_size=self.patch_size, sparsity=self.sparsity,
            n_atoms=self.n_atoms, ksvd_training=self.ksvd_training,
        )  # fmt: skip
        terms = {"exemplar scales and dictionaries": kept}
        if output_shape is None:
            terms["patches, K-SVD and codes of the exemplar"] = fit_peak - kept
            return terms
        canvas = self._canvas(output_shape)
        pixels = float(canvas[0]) * canvas[1]
        patches = pixels / (self.step * self.step)
        terms["image, gradient and histogram targets"] = pixels * (56.0 * c + 16.0) + 8.0 * n * n
        # the pursuit runs while the previous iteration's codes and coded patches are still
        # referenced (8 n + 8 dim bytes a patch): the traced peak of 128 -> 256 grey
        pursuit = 16.0 * patches * dim + 25.0 * n * patches + 130.0 * patches
        reassembly = 16.0 * patches * dim + 8.0 * n * patches + 80.0 * c * pixels
        terms["patch codes and reassembly"] = max(pursuit, reassembly)
        # the pursuit's n x K float64 arrays (correlations, their rows, codes: NumPy's and
        # Numba's, the same sizes every iteration) leave the heap fragmented: a model loaded
        # in a fresh process grows the resident set by 2.6 to 3.3 of them more than the
        # traced peak (48 MiB against 29, 128 -> 256 grey); two counted, the margin covers
        # the rest (docs/memory.md, "Every method at its defaults")
        terms["fragmented heap of the pursuit"] = 16.0 * n * patches
        terms["output image"] = output_bytes(c, output_shape) + 16.0 * c * pixel_count(output_shape)
        return terms

    # ---------------------------------------------------------------- sample
    def _canvas(self, shape: tuple[int, int]) -> tuple[int, int]:
        """The working canvas: whole grids of ``step`` at every scale, two patches wide or more."""
        q = self.step * 2 ** (self._scales - 1)
        return padded_canvas(shape, minimum=q * -(-2 * self.patch_size // self.step), multiple=q)

    def periodic_for(self, shape):
        """The patches lie on a periodic grid and the spectrum is imposed by FFT, on the working
        canvas (:meth:`_canvas`): the output wraps when it is the canvas itself, sides that are
        multiples of ``step * 2**(scales - 1)`` and at least two patches (``docs/tiling.md``)."""
        return self._canvas(shape) == tuple(shape)

    def _sample(self, shape, rng, callback):
        """Algorithm 1, steps 3-4, from the coarsest scale to the finest (section 4.3).

        Returns the image and the diagnostics: ``energy``, the energy (3) after every outer
        iteration (linear data term ``(1/Z)||Pi(u) - D W||^2``, coarsest scale first),
        ``energy_scale`` (the scale of each entry), and per scale, coarsest first,
        ``iterations`` and ``converged`` (the criterion of ``tolerance`` was met, at the
        latest on the ``n_outer``-th iteration; false for a scale the cap stopped first, and
        whenever ``tolerance`` is 0).
        """
        tau, step, s = self.patch_size, self.step, self.sparsity
        canvas = self._canvas(shape)
        seconds = {"coding": 0.0, "reconstruction": 0.0, "image_update": 0.0}
        energies: list[float] = []
        energy_scale: list[int] = []
        iterations: list[int] = []
        converged: list[bool] = []
        u = None
        for j in reversed(range(self._scales)):
            scale = self.model_.scales[j]
            report = Reporter(callback, f"scale {self._scales - j}/{self._scales}", self.n_outer)
            size = (canvas[0] >> j, canvas[1] >> j)
            grid = (size[0] // step, size[1] // step)
            n_patches = grid[0] * grid[1]
            budget = None
            if self._frequency:  # the frequencies F of eq. (4), rounded up
                budget = np.ceil(n_patches / scale.n_patches * scale.usage).astype(np.int64)
            if u is None:  # white noise with the exemplar's mean and deviation
                u = scale.mean + scale.std * rng.standard_normal(size + (len(scale.mean),))
            else:
                u = upsample_bicubic(u)
            reference = self._reference(scale, size)
            projector = HistogramMatcher(scale.sorted, size[0] * size[1], pca=scale.pca)
            # the weights and targets of the energy (6) at this scale
            power = box_power(size, tau)
            if self.lowpass_ref == "spectrum" and self.spectrum_weight > 0:
                power = np.maximum(power, self.spectrum_weight)
            energy = dict(alpha=self.alpha, beta=self._beta, box_power=power, reference=reference)
            dictionary = scale.dictionary
            gram = dictionary.T @ dictionary
            best, stalled, done, history = np.inf, 0, False, []
            for outer in range(self.n_outer):
                offset = rng.integers(step, size=2) if self.random_offset else np.zeros(2, dtype=int)
                shifted = np.roll(u, (-offset[0], -offset[1]), axis=(0, 1))
                clock = time.perf_counter()
                # coefficient update (section 4.2)
                patches, anchors = extract_patches(shifted, tau, stride=step, mode="periodic")
                codes = constrained_matching_pursuit(patches.T, dictionary, s, budget, gram=gram)
                coded = matmul(dictionary, codes).T
                seconds["coding"] += time.perf_counter() - clock
                clock = time.perf_counter()
                if self._graphcut:  # the non-linear reconstruction of section 4.1
                    recon = graphcut_reassemble(coded.reshape(grid + (tau, tau, u.shape[2])), step, size)
                else:
                    recon = average_patches(coded, anchors, size + (u.shape[2],), tau, mode="periodic")
                recon = np.roll(recon, (offset[0], offset[1]), axis=(0, 1))
                seconds["reconstruction"] += time.perf_counter() - clock
                clock = time.perf_counter()
                previous = u
                u = image_update(u, recon, projector, n_steps=self.n_inner, rng=rng, **energy)  # section 4.1
                seconds["image_update"] += time.perf_counter() - clock
                change = np.linalg.norm(u - previous) / max(np.linalg.norm(u), 1e-12)
                history.append(self._energy(u, coded, offset, projector, energy))
                if history[-1] < best * (1.0 - self.tolerance):
                    best, stalled = history[-1], 0
                else:  # the graph cuts and the greedy pursuit make the energy jitter
                    stalled += 1
                    done = self.tolerance > 0 and stalled >= PATIENCE
                if report.active:
                    info = {
                        "scale": j,
                        "n_patches": n_patches,
                        "budget": budget,
                        "usage": np.count_nonzero(codes, axis=1),
                        "relative_change": change,
                        "energy": history[-1],
                        "seconds": dict(seconds),
                    }
                    report(outer + 1, info=info)
                if done:
                    break
            energies += history
            energy_scale += [j] * len(history)
            iterations.append(len(history))
            converged.append(done)
        if self.lowpass_ref == "spectrum" and self._beta > 0 and self.final_rounds:
            u = self._final_rounds(u, rng)
        out = crop_to_output(u, shape)
        if self.final_histogram:
            finest = self.model_.scales[0]
            out = HistogramMatcher(finest.sorted, out.shape[0] * out.shape[1], pca=finest.pca)(out, rng)
        diagnostics = {
            "energy": np.asarray(energies),
            "energy_scale": np.asarray(energy_scale, dtype=np.int64),
            "iterations": np.asarray(iterations, dtype=np.int64),
            "converged": np.asarray(converged, dtype=bool),
        }
        return out, None, diagnostics

    def _energy(self, u, coded, offset, projector, energy) -> float:
        """The energy (3) of ``u`` and the codes of its (offset) grid, linear data term (eq. 6)."""
        shifted = np.roll(u, (-offset[0], -offset[1]), axis=(0, 1))
        terms = dict(energy)
        if isinstance(terms["reference"], np.ndarray):
            terms["reference"] = np.roll(terms["reference"], (-offset[0], -offset[1]), axis=(0, 1))
        return image_energy(shifted, coded, self.patch_size, self.step, projector, **terms)

    def _final_rounds(self, u: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Alternate the low-band spectrum step and the histogram ``final_rounds`` times.

        The iterations stop at a compromise between the sparse reconstruction, the histogram
        and the low-pass term; where the codes lack fine detail the histogram puts the
        missing variance in the low frequencies (local-mean spread 1.20 of the exemplar's
        on t4). Each round moves the low frequencies to the exemplar's modulus, weighted by
        the box filter's ``|h^|`` (the scales of the low-pass term only), then restores the
        histogram (``docs/methods/sparse.md``, "Final rounds").
        """
        finest = self.model_.scales[0]
        size = u.shape[:2]
        project = self._reference(finest, size)
        weight = np.sqrt(box_power(size, self.patch_size))
        histogram = HistogramMatcher(finest.sorted, size[0] * size[1], pca=finest.pca)
        for _ in range(self.final_rounds):
            u = histogram(lowpass_towards(u, project(u), weight), rng)
        return u

    def _reference(self, scale: SparseScale, size: tuple[int, int]):
        """``u_ref`` of the low-pass term: a spectrum projection, the mean colour or the exemplar."""
        image = scale.image
        if self.lowpass_ref == "spectrum":
            return SpectrumProjector(image, size)
        if self.lowpass_ref == "aligned":
            if image.shape[0] >= size[0] and image.shape[1] >= size[1]:
                return image[: size[0], : size[1]]
            warnings.warn(
                "lowpass_ref='aligned' needs an output no larger than the exemplar; using 'mean'",
                UserWarning,
                stacklevel=4,
            )
        return np.broadcast_to(scale.mean, size + (image.shape[2],))

    # ---------------------------------------------------------------- persistence
    def fitted_arrays(self) -> dict[str, np.ndarray]:
        """The learned dictionaries and statistics of every scale (:meth:`SparseModel.to_arrays`)."""
        self._require_fitted()
        return self.model_.to_arrays()

    def restore_fitted(self, exemplar: np.ndarray, arrays: dict[str, np.ndarray]) -> ConstrainedSparse:
        """Rebuild the saved model without running K-SVD again (``docs/persistence.md``)."""
        self._check_params()
        model = sparse_model_from_arrays(arrays, patch_size=self.patch_size)
        if self._scales > len(model.scales):
            raise InputError(
                f"mode {self.mode!r} needs {self._scales} scales but the saved model has {len(model.scales)}; "
                "save a model fitted in mode 'multiscale' or 'full'"
            )
        self.exemplar_ = np.asarray(exemplar, dtype=np.float64)
        self.model_ = model
        return self

    def fitted_state(self) -> dict[str, np.ndarray]:
        """Deprecated (texsyn 0.1): the fitted model as arrays in memory; use :func:`texsyn.save`."""
        warnings.warn("fitted_state() is deprecated; use texsyn.save", DeprecationWarning, stacklevel=2)
        self._require_fitted()
        params = np.array(json.dumps(self.get_params()))
        header = {"format_version": np.array(FORMAT_VERSION), "method": np.array(self.name), "params": params}
        return {**header, "exemplar": self.exemplar_, **self.model_.to_arrays()}

    @classmethod
    def from_fitted_state(cls, state, **params) -> ConstrainedSparse:
        """Deprecated (texsyn 0.1): rebuild from :meth:`fitted_state`; use :func:`texsyn.load`."""
        warnings.warn("from_fitted_state() is deprecated; use texsyn.load", DeprecationWarning, stacklevel=2)
        if (
            int(np.asarray(state["format_version"])) != FORMAT_VERSION
            or str(np.asarray(state["method"])) != cls.name
        ):
            raise InputError(f"not a fitted state of method {cls.name!r} in format version {FORMAT_VERSION}")
        with warnings.catch_warnings():  # a state of texsyn 0.1 names the seed random_state
            warnings.simplefilter("ignore", DeprecationWarning)
            saved = cls.canonical_params(json.loads(str(np.asarray(state["params"]))))
            params = cls.canonical_params(params)
        changed = sorted(k for k in params if k in cls.learned_params and params[k] != saved.get(k))
        if changed:
            raise InputError(
                f"cannot change {', '.join(changed)} of a loaded dictionary (they change what fit learned)"
            )
        arrays = {
            k: v for k, v in state.items() if k not in ("format_version", "method", "params", "exemplar")
        }
        return cls(**{**saved, **params}).restore_fitted(state["exemplar"], arrays)
