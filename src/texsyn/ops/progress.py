"""Progress: the one record methods report while they work, and the one reporter that sends it.

Every method, driver and front door reports through :class:`Reporter`; a user's
``callback`` receives :class:`Progress` records only (``docs/architecture.md``, "Shared
policies").
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

__all__ = ["Progress", "ProgressCallback", "Reporter"]


@dataclass(frozen=True)
class Progress:
    """What a method reports to ``callback`` while it works.

    Attributes
    ----------
    stage : str
        Short name of the current stage (``"blocks"``, ``"iteration"``, ``"pixels"``...).
    done, total : int
        Work units finished so far and in all for this stage.
    image : ndarray or None
        An intermediate image, when the method has one worth showing.
    info : dict or None
        Method-specific diagnostics (codes, usage counts, energies...).

    Examples
    --------
    >>> Progress("iteration", 3, 10)
    Progress(stage='iteration', done=3, total=10, image=None, info=None)
    """

    stage: str
    done: int
    total: int
    image: np.ndarray | None = None
    info: dict | None = None


ProgressCallback = Callable[[Progress], None]


class Reporter:
    """Sends :class:`Progress` records of one stage to an optional user callback.

    Drivers and methods take a ``Reporter`` (never a bare callable of their own shape), so
    that there is one progress shape from the innermost loop to the front doors.

    Parameters
    ----------
    callback : callable or None
        Receives each :class:`Progress`; ``None`` makes every call a no-op.
    stage : str
        Name of the stage reported.
    total : int
        Work units of the stage.

    Examples
    --------
    >>> seen = []
    >>> report = Reporter(seen.append, "pixels", 4)
    >>> report(2)
    >>> seen[0].stage, seen[0].done, seen[0].total
    ('pixels', 2, 4)
    >>> Reporter(None, "pixels", 4)(1)  # nobody listens: nothing happens
    """

    __slots__ = ("callback", "stage", "total")

    def __init__(self, callback: ProgressCallback | None, stage: str = "", total: int = 0):
        self.callback = callback
        self.stage = stage
        self.total = int(total)

    @property
    def active(self) -> bool:
        """Whether anyone listens."""
        return self.callback is not None

    @property
    def wants_images(self) -> bool:
        """Whether the listener shows intermediate images (compute them only when true).

        A callback that never looks at :attr:`Progress.image` says so with an attribute
        ``wants_images = False`` (the command line's progress bar does: a preview costs a
        colour conversion or a reconstruction per iteration, about 13 ms of a grouplet pass).
        """
        return self.callback is not None and getattr(self.callback, "wants_images", True)

    def __call__(
        self,
        done: int,
        total: int | None = None,
        *,
        image: np.ndarray | None = None,
        info: dict | None = None,
    ) -> None:
        """Report ``done`` units of ``total`` (the stage's total by default)."""
        if self.callback is not None:
            self.callback(
                Progress(self.stage, int(done), self.total if total is None else int(total), image, info)
            )

    def stage_of(self, stage: str, total: int = 0) -> Reporter:
        """A reporter of another stage that sends to the same callback."""
        return Reporter(self.callback, stage, total)

    def relabel(self, stage: str | None = None, total: int | None = None) -> ProgressCallback | None:
        """A callback that forwards another reporter's records under this stage and total.

        For a method that runs another method inside it (MSLG's final Portilla–Simoncelli
        pass, the first frame of an animation): the inner records keep their ``done``,
        ``image`` and ``info``; ``None`` when nobody listens.
        """
        if self.callback is None:
            return None
        outer = self.callback

        def forward(record: Progress) -> None:
            outer(
                Progress(
                    record.stage if stage is None else stage,
                    record.done,
                    record.total if total is None else total,
                    record.image,
                    record.info,
                )
            )

        forward.wants_images = getattr(outer, "wants_images", True)  # type: ignore[attr-defined]
        return forward
