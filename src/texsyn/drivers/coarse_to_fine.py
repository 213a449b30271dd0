"""The coarse-to-fine walk over a pyramid (``docs/architecture.md``, "Drivers").

Multiresolution synthesis methods share one loop: synthesise the coarsest level first, then
every finer level from the level just above it, down to the finest. Wei & Levoy (2000,
section 2) synthesise each Gaussian-pyramid level with the coarser level as context;
Gallagher & Kokaram grow the coarsest DT-CWT level and hand every source position down the
coefficient tree (``docs/methods/cwt.md``); the patch-valued wavelet inverse rebuilds one
level of coordinates after the other. What a level's synthesis is belongs to the method (the
``step``); the walk, its order and its progress reports are written here once.

Levels are 0-based, the finest first (``docs/architecture.md``, "Vocabulary"): level 0 is the
full resolution and level ``n_levels - 1`` the coarsest.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TypeVar

from ..ops.progress import Reporter

__all__ = ["coarse_to_fine"]

State = TypeVar("State")


def coarse_to_fine(
    step: Callable[[int, State | None], State],
    n_levels: int,
    *,
    start: State | None = None,
    reporter: Reporter | None = None,
    preview: Callable[[State], object] | None = None,
) -> list[State]:
    """Synthesise levels ``n_levels - 1, ..., 1, 0``, each from the one above it.

    Parameters
    ----------
    step : callable
        ``step(level, coarser) -> state``: the method's synthesis of one level. ``coarser``
        is the state returned for ``level + 1``; for the coarsest level
        (``level == n_levels - 1``) it is ``start``. A state is whatever the method carries
        from level to level (an image, a source map, a tuple of both...).
    n_levels : int
        Number of levels synthesised (at least 1).
    start : optional
        What the coarsest step receives as ``coarser``: ``None`` (the default) when the
        coarsest level is synthesised from nothing, or an already known coarser state (a
        seed, a coarse coordinate map).
    reporter : Reporter, optional
        Receives ``done = k`` (levels finished, ``k = 1 .. n_levels``) after each level; its
        ``total`` is the reporter's own (give ``n_levels`` when building it). Steps that
        report finer progress (pixels of a level) use their own reporter and leave this one
        out.
    preview : callable, optional
        ``preview(state) -> image`` sent with each report; computed only when someone
        listens.

    Returns
    -------
    list
        ``states[level]`` for ``level = 0 .. n_levels - 1``, 0-based, the finest first:
        ``states[0]`` is the result at full resolution.

    Examples
    --------
    >>> coarse_to_fine(lambda level, coarser: (coarser or "") + str(level), 3)
    ['210', '21', '2']
    >>> coarse_to_fine(lambda level, coarser: 2 * coarser, 2, start=1)
    [4, 2]
    """
    if n_levels < 1:
        raise ValueError(f"n_levels must be at least 1, got {n_levels}")
    states: list[State] = [None] * n_levels  # type: ignore[list-item]
    coarser = start
    for k, level in enumerate(reversed(range(n_levels))):
        coarser = states[level] = step(level, coarser)
        if reporter is not None and reporter.active:
            image = preview(coarser) if preview is not None and reporter.wants_images else None
            reporter(k + 1, image=image)  # type: ignore[arg-type]
    return states
