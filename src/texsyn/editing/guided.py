"""Guided synthesis: a guide map of the exemplar and one of the output say what goes where.

A user paints a label (or any) map over the exemplar (where the bricks are, where the moss
is) and one of the output's size; each output block is then chosen for its agreement with
what is already synthesised plus ``weight`` times the agreement of the two guides under it
(``docs/editing.md``). The loop is :meth:`texsyn.methods.Quilting.sample_guided`.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from .._validation import as_exemplar
from ..errors import InputError
from ..methods import SynthesisResult, get_method, make_method
from ..ops.progress import Progress

__all__ = ["GUIDED_METHODS", "synthesize_guided"]

#: the methods that follow guide maps (``docs/editing.md`` says why the others do not)
GUIDED_METHODS = ("quilting", "efros_leung")


def synthesize_guided(
    exemplar: np.ndarray,
    guide_source: np.ndarray,
    guide_target: np.ndarray,
    *,
    method: str = "quilting",
    weight: float = 1.0,
    rng: None | int | np.random.Generator = None,
    callback: Callable[[Progress], None] | None = None,
    **params,
) -> SynthesisResult:
    """A texture from ``exemplar`` whose guide follows ``guide_target``.

    Parameters
    ----------
    exemplar : ndarray, shape (H0, W0) or (H0, W0, 3)
    guide_source : ndarray, shape (H0, W0) or (H0, W0, G)
        The exemplar's guide (labels as grey levels or colours), values in [0, 1].
    guide_target : ndarray, shape (H, W) or (H, W, G)
        The output's guide, same channels; the output takes its size.
    method : {'quilting'}
    weight : float
        Weight of the guide's mean squared difference against the overlap's (>= 0).
    rng, callback
        As in :meth:`texsyn.TextureSynthesizer.sample`.
    **params
        Parameters of the method.

    Returns
    -------
    SynthesisResult
    """
    if method not in GUIDED_METHODS:
        get_method(method)
        raise InputError(
            f"method {method!r} does not follow guide maps; methods that do: {', '.join(GUIDED_METHODS)}"
        )
    if not np.isfinite(weight) or weight < 0:
        raise InputError(f"the guide weight must be a finite number >= 0, got {weight!r}")
    source = as_exemplar(guide_source, name="source guide")
    target = as_exemplar(guide_target, name="target guide")
    if source.ndim != target.ndim:
        raise InputError("the two guides must both be grey or both colour")
    synthesizer = make_method(method, **params).fit(exemplar)
    return synthesizer.sample_guided(source, target, weight=float(weight), rng=rng, callback=callback)
