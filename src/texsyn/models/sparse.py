"""What the ``sparse`` method learns: one dictionary of patch atoms per scale.

Tartavel, Gousseau and Peyré (2013), section 2 and Algorithm 1, steps 1-2: at each scale
``j`` of the exemplar's pyramid, a dictionary ``D_j`` of unit-norm atoms is learned by K-SVD
with exactly ``S``-sparse codes (eq. 1), the exemplar's patches are coded again with the
synthesis pursuit, and the number of patches using each atom (the frequencies of eq. 4,
before their rescaling to the output size) is kept, with what the histogram, low-pass and
initial-noise terms need. ``docs/methods/sparse.md`` maps each step to its function.

The model is a frozen dataclass built once by :func:`learn_sparse_model` (or read back by
:func:`sparse_model_from_arrays`); its arrays are read-only views, so sampling cannot change
it (``docs/architecture.md``, "Fitted state"). Models compare by identity (``eq=False``):
element-wise array comparison has no single truth value.
"""

from __future__ import annotations

import re
import time
import warnings
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from ..errors import InputError
from ..ops.color import ColorPCA, colour_space
from ..ops.linalg import worker_count
from ..ops.patches import as_channels, extract_patches
from ..ops.sparse import constrained_matching_pursuit, ksvd
from ..transforms.pyramids import crop_to_multiple, zoom_out

__all__ = ["SparseModel", "SparseScale", "learn_sparse_model", "sparse_model_from_arrays"]


def _frozen(array: np.ndarray, dtype: type) -> np.ndarray:
    """A read-only view of ``array`` as ``dtype`` (the original stays writable)."""
    out: np.ndarray = np.asarray(array, dtype=dtype).view()
    out.flags.writeable = False
    return out


@dataclass(frozen=True, eq=False)
class SparseScale:
    """The model of one scale ``j`` (Tartavel et al. 2013, sections 2 and 4.3).

    Attributes
    ----------
    dictionary : ndarray, shape (L, N)
        Unit-norm atoms ``D_j`` as columns (``L = tau^2 C``).
    usage : ndarray of int64, shape (N,)
        Exemplar patches whose code uses each atom, ``||w_0^n||_0`` of eq. (4).
    n_patches : int
        Number ``K_0`` of exemplar patches the usage counts come from.
    sorted : tuple of ndarray
        Sorted exemplar values per grey channel or colour PCA axis (the histogram term, eq. 5).
    pca : ColorPCA or None
        The exemplar's colour PCA basis (colour only).
    mean, std : ndarray, shape (C,)
        Per-channel mean and standard deviation (initial noise; 'mean' low-pass reference).
    image : ndarray, shape (h, w, C)
        The exemplar at this scale ('aligned' low-pass reference).

    Examples
    --------
    The fields also read as a mapping, as the dictionaries of texsyn 0.1 did:

    >>> scale = SparseScale(np.eye(2), np.array([1, 1]), 2, (np.arange(4.0),), None,
    ...                     np.zeros(1), np.ones(1), np.zeros((2, 2, 1)))
    >>> scale["n_patches"] == scale.n_patches
    True
    """

    dictionary: np.ndarray
    usage: np.ndarray
    n_patches: int
    sorted: tuple[np.ndarray, ...]
    pca: ColorPCA | None
    mean: np.ndarray
    std: np.ndarray
    image: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "dictionary", _frozen(self.dictionary, np.float64))
        object.__setattr__(self, "usage", _frozen(self.usage, np.int64))
        object.__setattr__(self, "n_patches", int(self.n_patches))
        object.__setattr__(self, "sorted", tuple(_frozen(v, np.float64) for v in self.sorted))
        for name in ("mean", "std", "image"):
            object.__setattr__(self, name, _frozen(getattr(self, name), np.float64))

    def __getitem__(self, key: str) -> Any:
        """Mapping access to the fields (``scale["usage"]``), kept from texsyn 0.1."""
        if key not in {f.name for f in fields(self)}:
            raise KeyError(key)
        return getattr(self, key)


@dataclass(frozen=True, eq=False)
class SparseModel:
    """Everything ``sample`` of the ``sparse`` method needs: one :class:`SparseScale` per scale.

    ``scales[0]`` is the finest (the cropped exemplar itself), ``scales[j]`` the exemplar
    zoomed out ``j`` times.
    """

    scales: tuple[SparseScale, ...]

    def to_arrays(self) -> dict[str, np.ndarray]:
        """The model as plain arrays (what :func:`texsyn.save` stores; ``docs/persistence.md``).

        Keys ``n_scales_fitted`` and, per scale ``j``, ``s{j}_dictionary``, ``s{j}_usage``,
        ``s{j}_n_patches``, ``s{j}_sorted`` (one row per channel or PCA axis), ``s{j}_mean``,
        ``s{j}_std`` and ``s{j}_image``; the PCA bases are recomputed from the images.
        """
        out: dict[str, np.ndarray] = {"n_scales_fitted": np.array(len(self.scales))}
        for j, scale in enumerate(self.scales):
            out[f"s{j}_dictionary"] = np.asarray(scale.dictionary)
            out[f"s{j}_usage"] = np.asarray(scale.usage)
            out[f"s{j}_n_patches"] = np.array(scale.n_patches)
            out[f"s{j}_sorted"] = np.stack(scale.sorted)
            out[f"s{j}_mean"] = np.asarray(scale.mean)
            out[f"s{j}_std"] = np.asarray(scale.std)
            out[f"s{j}_image"] = np.asarray(scale.image)
        return out


def learn_sparse_model(
    exemplar: np.ndarray,
    *,
    n_scales: int,
    patch_size: int,
    sparsity: int,
    n_atoms: int,
    ksvd_iterations: int,
    ksvd_training: int,
    seed: int,
) -> tuple[SparseModel, dict[str, float]]:
    """Learn the dictionaries of every scale (Algorithm 1, steps 1-2; section 4.3).

    The exemplar is cropped to a multiple of ``2^(n_scales - 1)`` and zoomed out once per
    coarser scale (Gaussian, sigma 1). At each scale all patches at stride 1 train a K-SVD
    dictionary (:func:`texsyn.ops.sparse.ksvd`, initialised and subsampled from
    ``numpy.random.default_rng(seed)``) and are coded again by the unconstrained pursuit
    (:func:`texsyn.ops.sparse.constrained_matching_pursuit` with no budget), whose non-zeros
    per atom are the usage counts. A scale with fewer than ``2 n_atoms`` patches uses
    ``max(sparsity + 1, K_0 // 2)`` atoms, with a warning.

    Returns
    -------
    model : SparseModel
    seconds : dict
        Time spent on the dictionaries and on the exemplar codes.

    Raises
    ------
    InputError
        A scale has fewer than ``2 (sparsity + 1)`` patches.
    """
    timings = {"dictionary": 0.0, "exemplar_codes": 0.0}
    ex = crop_to_multiple(as_channels(exemplar), 2 ** (n_scales - 1))
    rng = np.random.default_rng(seed)
    tau, s = patch_size, sparsity

    def usage(patches_t: np.ndarray, dictionary: np.ndarray) -> np.ndarray:
        start = time.perf_counter()
        codes = constrained_matching_pursuit(patches_t, dictionary, s, None)
        timings["exemplar_codes"] += time.perf_counter() - start
        return np.count_nonzero(codes, axis=1)

    # the exemplar codes of scale j use no randomness: they run on a second thread while
    # the next scale's K-SVD runs on this one (the pursuit kernel releases the GIL)
    pool = (
        ThreadPoolExecutor(max_workers=1, thread_name_prefix="texsyn-usage") if worker_count() > 1 else None
    )
    learned: list[tuple[np.ndarray, Future | np.ndarray, int, np.ndarray]] = []
    image = ex
    try:
        for j in range(n_scales):
            if j > 0:
                image = zoom_out(image, 1.0)
            patches, _ = extract_patches(image, tau)
            count = patches.shape[0]
            if count < 2 * (s + 1):
                raise InputError(
                    f"exemplar {ex.shape[1]}x{ex.shape[0]} gives {count} patches of side "
                    f"patch_size={tau} at scale {j} (n_scales={n_scales}); need at least "
                    f"{2 * (s + 1)}: use fewer scales, smaller patches or a larger exemplar"
                )
            atoms = n_atoms
            if count < 2 * atoms:
                atoms = max(s + 1, count // 2)
                warnings.warn(
                    f"scale {j} has only {count} exemplar patches; using {atoms} atoms "
                    f"instead of n_atoms={n_atoms}",
                    UserWarning,
                    stacklevel=5,
                )
            start = time.perf_counter()
            dictionary = ksvd(
                patches.T, atoms, s, n_iterations=ksvd_iterations, max_training=ksvd_training, rng=rng
            )
            timings["dictionary"] += time.perf_counter() - start
            used = usage(patches.T, dictionary) if pool is None else pool.submit(usage, patches.T, dictionary)
            learned.append((dictionary, used, count, image))
        scales = []
        for dictionary, used, count, image in learned:
            space = colour_space("pca", image)  # the histogram term's axes (section 3); grey stays grey
            coords = space.forward(image)
            scales.append(
                SparseScale(
                    dictionary=dictionary,
                    usage=used.result() if isinstance(used, Future) else used,
                    n_patches=count,
                    sorted=tuple(np.sort(coords[..., c], axis=None) for c in range(image.shape[2])),
                    pca=space.pca,
                    mean=image.mean(axis=(0, 1)),
                    std=image.std(axis=(0, 1)),
                    image=image,
                )
            )
    finally:
        if pool is not None:
            pool.shutdown(wait=True)
    return SparseModel(tuple(scales)), timings


def _entry(arrays: dict[str, np.ndarray], key: str, ndim: int) -> np.ndarray:
    if key not in arrays:
        raise InputError(f"saved sparse model has no array {key!r}")
    value = np.asarray(arrays[key])
    if value.ndim != ndim or not (np.issubdtype(value.dtype, np.number) or value.dtype == bool):
        raise InputError(
            f"saved sparse model has a malformed array {key!r} (shape {value.shape}, {value.dtype})"
        )
    return value


#: the arrays :meth:`SparseModel.to_arrays` writes, ``s<scale>_<field>`` and the scale count
ARRAY_NAME = re.compile(r"n_scales_fitted|s(1[0-5]|[0-9])_(image|dictionary|usage|n_patches|sorted|mean|std)")


def sparse_model_from_arrays(arrays: dict[str, np.ndarray], patch_size: int | None = None) -> SparseModel:
    """The model written by :meth:`SparseModel.to_arrays`, checked (``patch_size``: the side of
    the dictionary's atoms, when known).

    Raises
    ------
    InputError
        An array is missing, of the wrong rank, or inconsistent with the others.
    """
    n = int(_entry(arrays, "n_scales_fitted", 0))
    if not 1 <= n <= 16:
        raise InputError(f"saved sparse model has {n} scales")
    scales = []
    for j in range(n):
        image = _entry(arrays, f"s{j}_image", 3).astype(np.float64)
        dictionary = _entry(arrays, f"s{j}_dictionary", 2)
        usage = _entry(arrays, f"s{j}_usage", 1)
        sorted_values = _entry(arrays, f"s{j}_sorted", 2)
        mean, std = _entry(arrays, f"s{j}_mean", 1), _entry(arrays, f"s{j}_std", 1)
        channels = image.shape[2]
        if (
            usage.shape[0] != dictionary.shape[1]
            or sorted_values.shape[0] != channels
            or sorted_values.shape[1] < 1
            or mean.shape[0] != channels
            or std.shape[0] != channels
            or (patch_size is not None and dictionary.shape[0] != patch_size * patch_size * channels)
        ):
            raise InputError(f"saved sparse model has inconsistent arrays at scale {j}")
        values = (image, dictionary, usage, sorted_values, mean, std)
        if not all(np.all(np.isfinite(np.asarray(v, dtype=np.float64))) for v in values):
            raise InputError(f"saved sparse model holds NaN or infinite values at scale {j}")
        if np.any(np.asarray(usage) < 0) or np.any(np.asarray(std) < 0):
            raise InputError(f"saved sparse model holds negative usage counts or deviations at scale {j}")
        scales.append(
            SparseScale(
                dictionary=dictionary,
                usage=usage,
                n_patches=int(_entry(arrays, f"s{j}_n_patches", 0)),
                sorted=tuple(np.asarray(sorted_values, dtype=np.float64)),
                pca=colour_space("pca", image).pca,
                mean=mean,
                std=std,
                image=image,
            )
        )
    return SparseModel(tuple(scales))
