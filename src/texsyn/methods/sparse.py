"""Constrained sparse texture synthesis (Tartavel, Gousseau, Peyre 2013).

A dictionary of patch atoms is learned on the exemplar (K-SVD, S-sparse codes) together
with how often each atom is used. Synthesis minimises, by block-coordinate descent from
white noise, the energy (3) of the paper: sparse coding of the patches of the image on a
periodic grid, each atom used at most as often as in the exemplar (constrained matching
pursuit), the Wasserstein distance to the exemplar's histogram, and a low-pass term; the
linear patch averaging is replaced by graph-cut stitching, and a coarse-to-fine loop over
``J`` scales gives large-scale coherence.

References
----------
G. Tartavel, Y. Gousseau, G. Peyre, "Constrained sparse texture synthesis", SSVM 2013.
Implementation notes and resolutions of the paper's ambiguities: spec 04 (A1-A20).
"""

from __future__ import annotations

import json
import time
import warnings
from typing import Annotated

import numpy as np
from scipy import ndimage

from .._validation import OneOf, Range
from ..ops import (
    ColorPCA,
    HistogramMatcher,
    as_channels,
    average_patches,
    crop_to_multiple,
    extract_patches,
    zoom_out,
)
from ..ops.graphcut import graphcut_reassemble
from ..ops.sparse import constrained_matching_pursuit, ksvd
from ._base import Progress, TextureSynthesizer
from ._memory import shape_dims, output_bytes, pixel_count
from ..errors import InputError
from ..ops.linalg import matmul

__all__ = ["ConstrainedSparse", "MODES", "upsample_bicubic"]

#: the step-by-step study of the paper's Fig. 4, each mode adding one ingredient
MODES = ("basic", "frequency", "graphcut", "multiscale", "full")
#: fitted-state format written by :meth:`ConstrainedSparse.fitted_state`
FORMAT_VERSION = 1
#: parameters that change what ``fit`` learns (a loaded state cannot change them)
LEARNED = ("patch_size", "step", "n_scales", "sparsity", "n_atoms", "ksvd_iterations", "ksvd_training", "random_state")


def upsample_bicubic(image: np.ndarray) -> np.ndarray:
    """Periodic cubic-spline up-sampling by 2 aligned with ``S_2`` (spec 00, 4.3).

    Fine pixel ``j`` sits at coarse coordinate ``j / 2``, so ``up[::2, ::2] == image``.
    """
    img = as_channels(np.asarray(image, dtype=np.float64))
    h, w, channels = img.shape
    ii, jj = np.meshgrid(np.arange(2 * h) / 2.0, np.arange(2 * w) / 2.0, indexing="ij")
    out = np.empty((2 * h, 2 * w, channels))
    for c in range(channels):
        out[..., c] = ndimage.map_coordinates(img[..., c], [ii, jj], order=3, mode="grid-wrap")
    return out


def _box_power(shape: tuple[int, int], tau: int) -> np.ndarray:
    """``|h_hat|^2`` of the normalised ``tau x tau`` box on a periodic canvas."""
    box = np.zeros(shape)
    box[:tau, :tau] = 1.0 / tau**2
    return np.abs(np.fft.rfft2(box)) ** 2


def _lowpass_apply(e: np.ndarray, power: np.ndarray) -> np.ndarray:
    """``h_bar * h * e`` per channel (periodic)."""
    spec = np.fft.rfft2(e, axes=(0, 1)) * power[..., None]
    return np.fft.irfft2(spec, s=e.shape[:2], axes=(0, 1))


def image_update(
    u: np.ndarray,
    recon: np.ndarray,
    projector: HistogramMatcher,
    *,
    alpha: float,
    beta: float,
    box_power: np.ndarray,
    reference: np.ndarray,
    n_steps: int,
    rng: np.random.Generator | None,
) -> np.ndarray:
    """Gradient steps on the energy (6) for fixed codes (Tartavel et al. 2013, eq. 7).

    ``g = 2 (u - R) + 2 alpha (u - T_hist(u)) + 2 beta h_bar * h * (u - u_ref)`` with step
    ``eta = 1 / (2 (1 + alpha + beta))``, half the inverse Lipschitz constant (spec 04, A6).
    """
    eta = 1.0 / (2.0 * (1.0 + alpha + beta))
    for _ in range(n_steps):
        grad = 2.0 * (u - recon) + 2.0 * alpha * (u - projector(u, rng))
        if beta > 0:
            grad += 2.0 * beta * _lowpass_apply(u - reference, box_power)
        u = u - eta * grad
    return u


def image_energy(
    u: np.ndarray,
    coded: np.ndarray,
    tau: int,
    step: int,
    projector: HistogramMatcher,
    *,
    alpha: float,
    beta: float,
    box_power: np.ndarray,
    reference: np.ndarray,
) -> float:
    """``E_W(u) = (1/Z)||Pi(u) - D W||^2 + alpha N W_2^2 + beta ||h * (u - u_ref)||^2`` (eq. 6)."""
    patches, _ = extract_patches(u, tau, stride=step, mode="periodic")
    z = (tau / step) ** 2
    data = np.sum((patches - coded) ** 2) / z
    hist = np.sum((u - projector(u, None)) ** 2)
    low = 0.0
    if beta > 0:
        filtered = np.fft.irfft2(
            np.fft.rfft2(u - reference, axes=(0, 1)) * np.sqrt(box_power)[..., None], s=u.shape[:2], axes=(0, 1)
        )
        low = np.sum(filtered**2)
    return float(data + alpha * hist + beta * low)


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
        Reference of the low-pass term: 'mean' (the exemplar's mean colour, any size) or
        'aligned' (the exemplar itself; only when the output fits inside it).
    final_histogram : bool
        Impose the exemplar's histogram on the returned image.
    random_offset : bool
        Shift the patch grid by a random offset at every outer iteration.
    ksvd_iterations : int
        K-SVD iterations in fit.
    ksvd_training : int
        Training patches drawn per K-SVD iteration.
    tolerance : float
        Stop a scale early when the relative change of the image falls below this.
    random_state : int
        Seed of the randomness of fit (K-SVD initialisation and subsets).

    References
    ----------
    G. Tartavel, Y. Gousseau, G. Peyre, "Constrained sparse texture synthesis", SSVM 2013,
    sections 2-4, Algorithms 1-2, eqs. (1)-(12).

    Notes
    -----
    Limitations (paper, Fig. 3): very large-scale structures and noise-like micro-textures
    are poorly reproduced by the sparse model.
    """

    name = "sparse"
    summary = "Constrained sparse synthesis: learned dictionary, atom frequencies, graph cuts"
    reference = "Tartavel, Gousseau, Peyre, SSVM 2013"
    has_source_map = False

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
        lowpass_ref: Annotated[str, OneOf(("mean", "aligned"))] = "mean",
        final_histogram: bool = True,
        random_offset: bool = False,
        ksvd_iterations: Annotated[int, Range(1, 1000)] = 20,
        ksvd_training: Annotated[int, Range(10, 10**7)] = 8000,
        tolerance: Annotated[float, Range(0.0, 1.0)] = 1e-4,
        random_state: Annotated[int, Range(0, 2**32 - 1)] = 0,
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
        self.final_histogram = final_histogram
        self.random_offset = random_offset
        self.ksvd_iterations = ksvd_iterations
        self.ksvd_training = ksvd_training
        self.tolerance = tolerance
        self.random_state = random_state

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
            raise InputError(
                f"parameter 'step' of method 'sparse' must divide patch_size={tau}, got {step}"
            )
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
        return side, f"patch_size={self.patch_size} with {self._scales} scale(s) needs at least {side}x{side} pixels"

    # ---------------------------------------------------------------- fit
    def _fit(self, exemplar: np.ndarray) -> None:
        timings = {"dictionary": 0.0, "exemplar_codes": 0.0}
        ex = crop_to_multiple(as_channels(exemplar), 2 ** (self._scales - 1))
        rng = np.random.default_rng(self.random_state)
        tau, s = self.patch_size, self.sparsity
        scales = []
        image = ex
        for j in range(self._scales):
            if j > 0:
                image = zoom_out(image, 1.0)
            patches, _ = extract_patches(image, tau)
            n_patches = patches.shape[0]
            if n_patches < 2 * (s + 1):
                raise InputError(
                    f"exemplar {ex.shape[1]}x{ex.shape[0]} gives {n_patches} patches of side "
                    f"patch_size={tau} at scale {j} (n_scales={self._scales}); need at least "
                    f"{2 * (s + 1)}: use fewer scales, smaller patches or a larger exemplar"
                )
            n_atoms = self.n_atoms
            if n_patches < 2 * n_atoms:
                n_atoms = max(s + 1, n_patches // 2)
                warnings.warn(
                    f"scale {j} has only {n_patches} exemplar patches; using {n_atoms} atoms "
                    f"instead of n_atoms={self.n_atoms}",
                    UserWarning,
                    stacklevel=3,
                )
            start = time.perf_counter()
            dictionary = ksvd(
                patches.T, n_atoms, s, n_iterations=self.ksvd_iterations, max_training=self.ksvd_training, rng=rng
            )
            timings["dictionary"] += time.perf_counter() - start
            start = time.perf_counter()
            codes = constrained_matching_pursuit(patches.T, dictionary, s, None)
            timings["exemplar_codes"] += time.perf_counter() - start
            usage = np.count_nonzero(codes, axis=1)
            pca = ColorPCA(image) if image.shape[2] > 1 else None
            coords = pca.forward(image) if pca is not None else image
            scales.append(
                {
                    "dictionary": dictionary,
                    "usage": usage,
                    "n_patches": n_patches,
                    "sorted": [np.sort(coords[..., c], axis=None) for c in range(image.shape[2])],
                    "pca": pca,
                    "mean": image.mean(axis=(0, 1)),
                    "std": image.std(axis=(0, 1)),
                    "image": image,
                }
            )
        self.scales_ = scales
        self.fit_seconds_ = timings

    # ---------------------------------------------------------------- memory
    def memory_terms(self, exemplar_shape, output_shape=None) -> dict[str, float]:
        """Patches and codes of every exemplar patch (fit); codes of the output patches (sample).

        Fitting holds all ``K`` exemplar patches of the finest scale (``K x tau^2 C`` floats),
        K-SVD's batch OMP on ``ksvd_training`` of them and the constrained matching pursuit
        of all of them (``n_atoms x K`` correlations and codes); sampling holds the codes of
        the output patches and the graph-cut reassembly (``docs/memory.md``).
        """
        h, w, c = shape_dims(exemplar_shape)
        tau, s = self.patch_size, self.sparsity
        dim = tau * tau * c
        big = 2 ** (self._scales - 1)
        hc, wc = (h // big) * big, (w // big) * big
        kept, fit_peak = 8.0 * h * w * c, 0.0
        atoms = []
        for j in range(self._scales):
            sh, sw = hc >> j, wc >> j
            k = float(max(0, sh - tau + 1) * max(0, sw - tau + 1))
            n = self.n_atoms if k >= 2 * self.n_atoms else max(s + 1, int(k) // 2)
            atoms.append(n)
            t = min(k, float(self.ksvd_training))
            ksvd = 64.0 * t * n + 24.0 * dim * t
            pursuit = 17.0 * n * k + 130.0 * k
            fit_peak = max(fit_peak, kept + 8.0 * k * dim + max(8.0 * k * dim, ksvd, pursuit))
            kept += 8.0 * dim * n + 8.0 * k + 16.0 * sh * sw * c * (j > 0) + 8.0 * sh * sw * c
        terms = {"exemplar scales and dictionaries": kept}
        if output_shape is None:
            terms["patches, K-SVD and codes of the exemplar"] = fit_peak - kept
            return terms
        canvas = self._canvas(output_shape)
        pixels = float(canvas[0]) * canvas[1]
        n = atoms[0]
        patches = pixels / (self.step * self.step)
        terms["image, gradient and histogram targets"] = pixels * (56.0 * c + 16.0) + 8.0 * n * n
        pursuit = 8.0 * patches * dim + 17.0 * n * patches + 130.0 * patches
        reassembly = 16.0 * patches * dim + 8.0 * n * patches + 80.0 * c * pixels
        terms["patch codes and reassembly"] = max(pursuit, reassembly)
        terms["output image"] = output_bytes(c, output_shape) + 16.0 * c * pixel_count(output_shape)
        return terms

    # ---------------------------------------------------------------- sample
    def _canvas(self, shape: tuple[int, int]) -> tuple[int, int]:
        q = self.step * 2 ** (self._scales - 1)
        least = -(-2 * self.patch_size // self.step)
        return (q * max(-(-shape[0] // q), least), q * max(-(-shape[1] // q), least))

    def _sample(self, shape, rng, callback):
        tau, step, s = self.patch_size, self.step, self.sparsity
        canvas = self._canvas(shape)
        seconds = {"coding": 0.0, "reconstruction": 0.0, "image_update": 0.0}
        u = None
        for j in reversed(range(self._scales)):
            scale = self.scales_[j]
            size = (canvas[0] >> j, canvas[1] >> j)
            grid = (size[0] // step, size[1] // step)
            n_patches = grid[0] * grid[1]
            budget = None
            if self._frequency:
                budget = np.ceil(n_patches / scale["n_patches"] * scale["usage"]).astype(np.int64)
            if u is None:
                u = scale["mean"] + scale["std"] * rng.standard_normal(size + (len(scale["mean"]),))
            else:
                u = upsample_bicubic(u)
            reference = self._reference(scale, size)
            projector = HistogramMatcher(scale["sorted"], size[0] * size[1], pca=scale["pca"])
            power = _box_power(size, tau)
            dictionary = scale["dictionary"]
            gram = dictionary.T @ dictionary
            for outer in range(self.n_outer):
                offset = rng.integers(step, size=2) if self.random_offset else np.zeros(2, dtype=int)
                shifted = np.roll(u, (-offset[0], -offset[1]), axis=(0, 1))
                clock = time.perf_counter()
                patches, anchors = extract_patches(shifted, tau, stride=step, mode="periodic")
                codes = constrained_matching_pursuit(patches.T, dictionary, s, budget, gram=gram)
                coded = matmul(dictionary, codes).T
                seconds["coding"] += time.perf_counter() - clock
                clock = time.perf_counter()
                if self._graphcut:
                    recon = graphcut_reassemble(coded.reshape(grid + (tau, tau, u.shape[2])), step, size)
                else:
                    recon = average_patches(coded, anchors, size + (u.shape[2],), tau, mode="periodic")
                recon = np.roll(recon, (offset[0], offset[1]), axis=(0, 1))
                seconds["reconstruction"] += time.perf_counter() - clock
                clock = time.perf_counter()
                previous = u
                u = image_update(
                    u, recon, projector, alpha=self.alpha, beta=self._beta, box_power=power,
                    reference=reference, n_steps=self.n_inner, rng=rng,
                )
                seconds["image_update"] += time.perf_counter() - clock
                change = np.linalg.norm(u - previous) / max(np.linalg.norm(u), 1e-12)
                if callback is not None:
                    info = {
                        "scale": j,
                        "n_patches": n_patches,
                        "budget": budget,
                        "usage": np.count_nonzero(codes, axis=1),
                        "relative_change": change,
                        "seconds": dict(seconds),
                    }
                    callback(Progress(f"scale {self._scales - j}/{self._scales}", outer + 1, self.n_outer, info=info))
                if change < self.tolerance:
                    break
        out = u[: shape[0], : shape[1]]
        if self.final_histogram:
            out = HistogramMatcher(self.scales_[0]["sorted"], out.shape[0] * out.shape[1], pca=self.scales_[0]["pca"])(out, rng)
        return out, None

    def _reference(self, scale: dict, size: tuple[int, int]) -> np.ndarray:
        image = scale["image"]
        if self.lowpass_ref == "aligned":
            if image.shape[0] >= size[0] and image.shape[1] >= size[1]:
                return image[: size[0], : size[1]]
            warnings.warn(
                "lowpass_ref='aligned' needs an output no larger than the exemplar; using 'mean'",
                UserWarning,
                stacklevel=4,
            )
        return np.broadcast_to(scale["mean"], size + (image.shape[2],))

    # ---------------------------------------------------------------- persistence
    def fitted_state(self) -> dict[str, np.ndarray]:
        """Everything ``fit`` learned, as plain arrays (for :func:`texsyn.io.save_fitted`)."""
        self._require_fitted()
        state: dict[str, np.ndarray] = {
            "format_version": np.array(FORMAT_VERSION),
            "method": np.array(self.name),
            "params": np.array(json.dumps(self.get_params())),
            "exemplar": self.exemplar_,
            "n_scales_fitted": np.array(len(self.scales_)),
        }
        for j, sc in enumerate(self.scales_):
            state[f"s{j}_dictionary"] = sc["dictionary"]
            state[f"s{j}_usage"] = sc["usage"]
            state[f"s{j}_n_patches"] = np.array(sc["n_patches"])
            state[f"s{j}_sorted"] = np.stack(sc["sorted"])
            state[f"s{j}_mean"] = sc["mean"]
            state[f"s{j}_std"] = sc["std"]
            state[f"s{j}_image"] = sc["image"]
        return state

    @classmethod
    def from_fitted_state(cls, state, **params) -> "ConstrainedSparse":
        """Rebuild a fitted instance; ``params`` may change sampling parameters only."""
        version = int(np.asarray(state["format_version"]))
        if version != FORMAT_VERSION:
            raise InputError(f"fitted state has format_version {version}; this texsyn reads {FORMAT_VERSION}")
        if str(np.asarray(state["method"])) != cls.name:
            raise InputError(f"fitted state is for method {str(np.asarray(state['method']))!r}, not {cls.name!r}")
        saved = json.loads(str(np.asarray(state["params"])))
        changed = sorted(k for k in params if k in LEARNED and params[k] != saved.get(k))
        if changed:
            raise InputError(
                f"cannot change {', '.join(changed)} of a loaded dictionary (they change what fit learned)"
            )
        unknown = sorted(set(params) - set(cls.param_specs()))
        if unknown:
            raise InputError(f"unknown parameter {unknown[0]!r} for method {cls.name!r}")
        method = cls(**{**saved, **params})
        method._check_params()
        fitted = int(np.asarray(state["n_scales_fitted"]))
        if method._scales > fitted:
            raise InputError(
                f"mode {method.mode!r} needs {method._scales} scales but the saved state has {fitted}; "
                "save a model fitted in mode 'multiscale' or 'full'"
            )
        method.exemplar_ = np.asarray(state["exemplar"], dtype=np.float64)
        scales = []
        for j in range(int(np.asarray(state["n_scales_fitted"]))):
            image = np.asarray(state[f"s{j}_image"], dtype=np.float64)
            scales.append(
                {
                    "dictionary": np.asarray(state[f"s{j}_dictionary"], dtype=np.float64),
                    "usage": np.asarray(state[f"s{j}_usage"], dtype=np.int64),
                    "n_patches": int(np.asarray(state[f"s{j}_n_patches"])),
                    "sorted": list(np.asarray(state[f"s{j}_sorted"], dtype=np.float64)),
                    "pca": ColorPCA(image) if image.shape[2] > 1 else None,
                    "mean": np.asarray(state[f"s{j}_mean"], dtype=np.float64),
                    "std": np.asarray(state[f"s{j}_std"], dtype=np.float64),
                    "image": image,
                }
            )
        method.scales_ = scales
        return method
