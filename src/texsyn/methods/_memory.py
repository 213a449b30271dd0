"""Byte counts of the arrays the building blocks allocate, for the methods' memory estimates.

Each function models one building block from shapes and parameters alone (no array is made),
so that a method can refuse work that would not fit in ``TEXSYN_MEMORY_LIMIT`` before it
starts (:meth:`texsyn.methods.TextureSynthesizer.memory_terms`, ``docs/memory.md``). The
counts follow the code: float64 is 8 bytes, complex128 16, a real FFT of ``h x w`` has
``h (w // 2 + 1)`` coefficients; "kept" arrays live as long as the fitted model, "transient"
ones only during one call.
"""

from __future__ import annotations

__all__: list[str] = []


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


def nonparametric_bytes(
    h: int, w: int, c: int, window: int, output_shape: tuple[int, int] | None
) -> tuple[float, float]:
    """``(kept, transient)`` bytes of :class:`~texsyn.ops.nonparametric.NonParametricSampler`.

    The sampler keeps the stacked bank ``[patches^2, -2 patches]`` of all ``K`` windows of the
    ``h x w x c`` exemplar (``16 K w^2 c`` bytes). With ``output_shape=None`` the transient is
    that of its construction (patch extraction and the squares); otherwise that of growing a
    texture of that size: the padded canvas, its masks and one batch of searches, whose size
    is bounded by the length of the growing front.
    """
    k = float(max(1, (h - window + 1) * (w - window + 1)))
    dim = float(window * window * c)
    kept = 16.0 * k * dim + 16.0 * k
    if output_shape is None:
        return kept, 24.0 * k * dim
    oh, ow = output_shape[:2]
    r = window // 2
    padded = float(oh + 2 * r) * float(ow + 2 * r)
    cap = max(8, min(256, (1 << 23) // int(k)))
    batch = float(min(cap, max(8, (oh + ow) // (r + 1))))
    grow = padded * (8.0 * c + 33.0) + 16.0 * float(oh) * float(ow) + 64.0 * (oh + ow + 8 * r)
    grow += batch * (48.0 * dim + 16.0 * k + 24.0 * window * window)
    return kept, grow
