"""The alternating-projections loop (``docs/architecture.md``, "Drivers").

Heeger & Bergen (1995), Portilla & Simoncelli (2000, section 4) and Peyré's grouplet
synthesis (2008, section 4) all start from noise and repeat one step that projects the
current image onto each constraint set in turn. The step is the method's; the loop, its
progress reports and its stopping rule are written here once.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TypeVar

from ..ops.progress import Reporter

__all__ = ["alternate_projections"]

State = TypeVar("State")


def alternate_projections(
    state: State,
    step: Callable[[State, int], State],
    n_iterations: int,
    *,
    reporter: Reporter | None = None,
    preview: Callable[[State], object] | None = None,
    start: int = 0,
) -> State:
    """Apply ``step`` ``n_iterations`` times, reporting after each.

    Parameters
    ----------
    state
        The starting point (usually histogram-matched noise), in the method's own
        representation (an image, channels, coefficients).
    step : callable
        ``step(state, iteration) -> state``: one pass of every projection.
    n_iterations : int
        Number of passes.
    reporter : Reporter, optional
        Receives ``done = start + k`` for ``k = 1..n_iterations``.
    preview : callable, optional
        ``preview(state) -> image`` shown with each report, computed only when someone listens.
    start : int
        Iterations already done (a refinement that continues a run).

    Returns
    -------
    The state after the last pass.

    Examples
    --------
    >>> alternate_projections(1, lambda x, k: 2 * x, 3)
    8
    """
    for k in range(n_iterations):
        state = step(state, k)
        if reporter is not None and reporter.active:
            image = preview(state) if preview is not None and reporter.wants_images else None
            reporter(start + k + 1, image=image)  # type: ignore[arg-type]
    return state
