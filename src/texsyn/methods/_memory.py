"""Byte counts of the arrays the building blocks allocate, for the methods' memory estimates.

Each function models one building block from shapes and parameters alone (no array is made),
so that a method can refuse work that would not fit in ``TEXSYN_MEMORY_LIMIT`` before it
starts (:meth:`texsyn.methods.TextureSynthesizer.memory_terms`, ``docs/memory.md``). The
counts follow the code: float64 is 8 bytes, complex128 16, a real FFT of ``h x w`` has
``h (w // 2 + 1)`` coefficients; "kept" arrays live as long as the fitted model, "transient"
ones only during one call.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__: list[str] = []

#: ``memory_margin`` of the methods whose terms were checked against the measured peaks of
#: ``benchmarks/bench_methods.py`` (128 -> 256 and 128 -> 1024 colour, resident growth after
#: a warm-up): their terms count the arrays alive at the peak, so 5 % covers the allocator's
#: slack and the estimate stays an upper bound within 25 % of the peak (``docs/memory.md``,
#: "Estimate against measurement")
CALIBRATED_MARGIN = 1.05


def planned_exemplar_shape(image: Any) -> tuple[int, ...] | None:
    """The shape :func:`texsyn._validation.as_exemplar` would give ``image``, read without converting it.

    For the memory check of :meth:`TextureSynthesizer.fit` before the float64 conversion of
    a large array. ``None`` when the input is not an array of a shape ``as_exemplar``
    accepts (it then raises the precise error itself).

    Examples
    --------
    >>> planned_exemplar_shape(np.zeros((4, 5, 4), dtype=np.uint8))
    (4, 5, 3)
    >>> planned_exemplar_shape("gravel.png") is None
    True
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


def shape_dims(shape: tuple[int, ...]) -> tuple[int, int, int]:
    """``(H, W, C)`` of an image shape ``(H, W)`` or ``(H, W, C)`` (C = 1 for grey)."""
    return int(shape[0]), int(shape[1]), int(shape[2]) if len(shape) > 2 else 1


def pixel_count(shape: tuple[int, ...]) -> float:
    """Number of pixels of a shape ``(H, W, ...)``, as a float (no overflow)."""
    return float(shape[0]) * float(shape[1])


def output_bytes(channels: int, output_shape: tuple[int, ...]) -> float:
    """What :meth:`TextureSynthesizer._as_output` adds: a clipped float64 copy, then float32."""
    return 12.0 * channels * pixel_count(output_shape)


def fft_search_bytes(h: int, w: int, c: int, *, masks: int = 3) -> tuple[float, float, float]:
    """``(kept, build, query)`` bytes of :class:`~texsyn.ops.FFTPatchSearch` on ``h x w x c``.

    ``kept``: the channel spectra and the spectra of the squares; ``build``: the transient of
    the constructor; ``query``: the transient of one ``distances`` call plus an energy cache
    of ``masks`` distinct weight windows.
    """
    half = float(h) * (w // 2 + 1)
    kept = 16.0 * half * (2 * c + 1 if c > 1 else 2)
    build = 8.0 * h * w * c + 8.0 * h * w + 16.0 * half * c
    query = 16.0 * half * (3 * c + 2) + 8.0 * float(h) * w * (3 + masks)
    return kept, build, query


def fft_search_terms(
    exemplar_shape: tuple[int, ...], *, masks: int, fitting: bool
) -> tuple[dict[str, float], float]:
    """Memory terms of a method whose model is one :class:`~texsyn.ops.FFTPatchSearch` of the exemplar.

    Returns the terms every such method starts from (the exemplar and its spectra, plus their
    construction when ``fitting``) and the transient bytes of one query (:func:`fft_search_bytes`).
    """
    h, w, c = shape_dims(exemplar_shape)
    kept, build, query = fft_search_bytes(h, w, c, masks=masks)
    terms = {"exemplar and its spectra": 8.0 * h * w * c + kept}
    if fitting:
        terms["spectra construction"] = build
    return terms, query


def nonparametric_bytes(
    h: int, w: int, c: int, window: int, output_shape: tuple[int, int] | None, *, screened: bool = False
) -> tuple[float, float]:
    """``(kept, transient)`` bytes of :class:`~texsyn.ops.nonparametric.NonParametricSampler`.

    The sampler keeps the stacked bank ``[patches^2, -2 patches]`` of all ``K`` windows of the
    ``h x w x c`` exemplar (``16 K w^2 c`` bytes) and the float32 bank of the exact search's
    lower bounds, stored twice (``8 K n``, ``n = (|disc| - 1) (1 + min(c, 2))``). With
    ``output_shape=None`` the transient is that of its construction (patch extraction and the
    squares); otherwise that of growing a texture of that size: the padded canvas, its masks,
    one batch of searches, whose size is bounded by the length of the growing front, and two
    chunks of float32 lower bounds (``2 x 4 K'`` bytes a row, ``K'`` the window count rounded
    up to 2048, ``max(128, 2^22 / K)`` rows or about a pass, whichever is shorter; one chunk
    when a screened sampler's passes fit in one; ``docs/methods/efros_leung.md``).

    ``screened``: the construction of a sampler that screens (a plain exemplar, as
    Efros-Leung's) holds the windows once (``8 K w^2 c``) and the float32 bounds'
    construction (``16 K n``), measured (``docs/memory.md``, "Second round"), instead of
    ``24 K w^2 c``. Its growth counts both the chunks of bounds and a batch's search: a
    batch whose screen is not sure is searched while the chunks are kept, 2048 windows at a
    time (:meth:`~texsyn.ops.nonparametric.NonParametricSampler.match_in_blocks`).
    """
    k = float(max(1, (h - window + 1) * (w - window + 1)))
    dim = float(window * window * c)
    grid = np.arange(window) - window // 2
    disc = float(np.count_nonzero(grid[:, None] ** 2 + grid[None, :] ** 2 <= 16))
    screen = (disc - 1) * (1 + min(c, 2))
    kept = 16.0 * k * dim + 16.0 * k + 8.0 * k * screen + 16.0 * float(h * w * c)
    if output_shape is None:
        return kept, (8.0 * k * dim + 16.0 * k * screen) if screened else 24.0 * k * dim
    oh, ow = output_shape[:2]
    r = window // 2
    padded = float(oh + 2 * r) * float(ow + 2 * r)
    cap = max(8, min(256, (1 << 23) // int(k)))
    batch = float(min(cap, max(8, (oh + ow) // (r + 1))))
    if screened:  # the padded values and mask, the front's mask and the int64 source map
        grow = padded * (8.0 * c + 2.0) + 17.0 * float(oh) * float(ow) + 64.0 * (oh + ow + 8 * r)
    else:
        grow = padded * (8.0 * c + 33.0) + 16.0 * float(oh) * float(ow) + 64.0 * (oh + ow + 8 * r)
    # a screened sampler searches its rare unsure batch 2048 windows at a time (match_in_blocks)
    searched = 17.0 * min(k, 2048.0) if screened else 16.0 * k
    searches = batch * (48.0 * dim + searched + 24.0 * window * window)
    # a buffer of bounds has room for a whole chunk, however short the passes are, and never
    # more rows than the output has pixels (texsyn.drivers.raster._ExactPass: screen_rows)
    chunk = min(float(max(128, (1 << 22) // int(k))), padded)
    buffers = 2.0
    if screened:
        chunk = min(chunk, float(oh) * float(ow))
        # the second buffer is made for a pass of more pixels than a chunk: a pass is the
        # growing front, at most 2 (oh + ow) pixels (measured), counted twice for the pixels
        # a pass leaves unfilled (docs/memory.md, "Every method at its defaults")
        buffers = 1.0 if 4.0 * (oh + ow) <= chunk else 2.0
    else:
        chunk = min(chunk, float(oh + ow))
    columns = -(-k // 2048) * 2048  # the bounds and their minima by blocks of 64
    bounds = buffers * chunk * (4.0625 * columns + 16.0 * screen + 8.0 * dim)
    grow += searches + bounds + 24.0 * k
    return kept, grow


def sparse_fit_bytes(
    h: int, w: int, c: int, *, scales: int, patch_size: int, sparsity: int, n_atoms: int, ksvd_training: int
) -> tuple[float, float, int]:
    """``(kept, peak, atoms)`` of fitting the ``sparse`` model on an ``h x w x c`` exemplar.

    ``kept``: the exemplar's scales, their dictionaries and statistics; ``peak``: the largest
    of kept plus one scale's ``K`` patches with K-SVD's batch OMP on ``ksvd_training`` of them
    or the pursuit of all of them (``N x K`` correlations and codes); ``atoms``: the
    dictionary size at the finest scale (reduced where a scale has fewer than ``2 N``
    patches, as :func:`texsyn.models.sparse.learn_sparse_model` does).
    """
    tau, s = patch_size, sparsity
    dim = tau * tau * c
    big = 2 ** (scales - 1)
    hc, wc = (h // big) * big, (w // big) * big
    kept, peak = 8.0 * h * w * c, 0.0
    atoms = []
    for j in range(scales):
        sh, sw = hc >> j, wc >> j
        k = float(max(0, sh - tau + 1) * max(0, sw - tau + 1))
        n = n_atoms if k >= 2 * n_atoms else max(s + 1, int(k) // 2)
        atoms.append(n)
        t = min(k, float(ksvd_training))
        # batch OMP's correlations, their working copy and the codes, the SVD updates'
        # residuals: K-SVD alone peaks at 121 MiB (grey) and 153 MiB (colour) for T = 8000,
        # n = 384, against 143 and 196 here (docs/memory.md, "Second round")
        ksvd = 40.0 * t * n + 24.0 * dim * t
        pursuit = 17.0 * n * k + 130.0 * k
        peak = max(peak, kept + 8.0 * k * dim + max(8.0 * k * dim, ksvd, pursuit))
        kept += 8.0 * dim * n + 8.0 * k + 16.0 * sh * sw * c * (j > 0) + 8.0 * sh * sw * c
    return kept, peak, atoms[0]
