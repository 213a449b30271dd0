"""Deliberate breakage of one method's output, to prove that its tests can fail.

``tests/test_sabotage.py`` runs each method's tests (the tests marked
``@pytest.mark.method("NAME")``) in a fresh pytest process with

    TEXSYN_SABOTAGE=KIND  TEXSYN_SABOTAGE_METHOD=NAME

and asserts that they fail. ``conftest.py`` calls :func:`install` at start-up; with the
variables set, it wraps the public outputs of the named method:

- ``shuffle``: the output's pixels are permuted at random (same histogram, no structure);
  a source map is permuted with them, so it still "explains" the output;
- ``blur``: the output is blurred (Gaussian, sigma 1.5 pixels): fine detail is lost;
- ``freeze`` (``animate`` only): every frame is a copy of the first;
- ``independent`` (``animate`` only): every frame is an independent static synthesis (seeds
  the tests do not use for their own references);
- ``stripes`` (``animate`` only): the paper's literal loop (``advection='paper'``), which
  keeps band energies but turns the material into smooth stripes; loops, which it cannot
  make, are left alone.

``NAME`` is a method of the registry, ``modify`` (``PatchWavelet.modify``) or ``animate``
(``Grouplets.animate``). The wrapped functions are the ones tests reach through the public
API: ``sample``/``sample_with_map`` (hence ``texsyn.synthesize``), ``synthesize_along``,
``modify`` and ``animate``.
"""

from __future__ import annotations

import dataclasses
import functools
import os

import numpy as np
from scipy.ndimage import gaussian_filter

KINDS = ("shuffle", "blur", "freeze", "independent", "stripes")


def _shuffle(image: np.ndarray, source_map: np.ndarray | None, seed: int = 12345):
    h, w = image.shape[:2]
    order = np.random.default_rng(seed).permutation(h * w)
    flat = image.reshape(h * w, -1)[order].reshape(image.shape)
    if source_map is not None:
        source_map = source_map.reshape(h * w, -1)[order].reshape(source_map.shape)
    return flat, source_map


def _blur(image: np.ndarray) -> np.ndarray:
    sigma = (1.5, 1.5, 0) if image.ndim == 3 else 1.5
    return np.clip(gaussian_filter(image.astype(np.float64), sigma, mode="wrap"), 0, 1).astype(image.dtype)


def _broken(kind: str, image: np.ndarray, source_map: np.ndarray | None):
    if kind == "shuffle":
        return _shuffle(image, source_map)
    if kind == "blur":
        return _blur(image), source_map
    return image, source_map


def install() -> str | None:
    """Wrap the named method's outputs if ``TEXSYN_SABOTAGE`` is set; return a description."""
    kind = os.environ.get("TEXSYN_SABOTAGE")
    target = os.environ.get("TEXSYN_SABOTAGE_METHOD")
    if not kind or not target:
        return None
    if kind not in KINDS:
        raise ValueError(f"TEXSYN_SABOTAGE must be one of {KINDS}, got {kind!r}")
    import texsyn
    from texsyn.methods import SynthesisResult, TextureSynthesizer
    from texsyn.methods.grouplets import Frame, Grouplets
    from texsyn.methods.patch_wavelet import PatchWavelet

    if target in texsyn.METHODS and kind in ("shuffle", "blur"):
        original = TextureSynthesizer.sample_with_map

        @functools.wraps(original)
        def sample_with_map(self, *args, **kwargs):
            result = original(self, *args, **kwargs)
            if self.name != target:
                return result
            image, source = _broken(kind, result.image, result.source_map)
            return SynthesisResult(image=image, source_map=source)

        TextureSynthesizer.sample_with_map = sample_with_map
        if target == "grouplets":
            along = Grouplets.synthesize_along

            @functools.wraps(along)
            def synthesize_along(self, *args, **kwargs):
                return _broken(kind, along(self, *args, **kwargs), None)[0]

            Grouplets.synthesize_along = synthesize_along
    elif target == "modify" and kind in ("shuffle", "blur"):
        modify = PatchWavelet.modify

        @functools.wraps(modify)
        def broken_modify(self, *args, **kwargs):
            out = modify(self, *args, **kwargs)

            def one(m):
                image, source = _broken(kind, m.image, m.source_map)
                return dataclasses.replace(m, image=image, source_map=source)

            return [one(m) for m in out] if isinstance(out, list) else one(out)

        PatchWavelet.modify = broken_modify
    elif target == "animate":
        animate = Grouplets.animate

        @functools.wraps(animate)
        def broken_animate(self, n_frames=60, shape=None, *, rng=None, callback=None, loop=0):
            if kind == "stripes":
                if loop:
                    yield from animate(self, n_frames, shape, rng=rng, callback=callback, loop=loop)
                    return
                kept, self.advection = self.advection, "paper"
                try:
                    yield from animate(self, n_frames, shape, rng=rng, callback=callback)
                finally:
                    self.advection = kept
                return
            first = None
            for frame in animate(self, n_frames, shape, rng=rng, callback=callback, loop=loop):
                if kind == "freeze":
                    first = frame.image if first is None else first
                    image = first
                elif kind == "independent":
                    size = frame.image.shape[:2]
                    image = self._as_output(
                        self._along(frame.flow, np.random.default_rng(70000 + frame.index), None)
                    )
                    image = image if image.shape[:2] == size else image[: size[0], : size[1]]
                else:
                    image = _broken(kind, frame.image, None)[0]
                yield Frame(frame.index, image, frame.flow)

        Grouplets.animate = broken_animate
    else:
        raise ValueError(f"no sabotage {kind!r} for {target!r}")
    return f"sabotage {kind} of {target}"
