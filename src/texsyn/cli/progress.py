"""The progress display of the command line: the one adapter from texsyn's progress records.

Every command passes a :class:`ProgressBar` as the ``callback`` of the API it calls; it
receives the :class:`~texsyn.ops.progress.Progress` records every method reports
(``docs/architecture.md``, "Progress") and draws them as a rich bar on stderr.
"""

from __future__ import annotations

import time
from typing import Any

from ..ops.progress import Progress

__all__ = ["ProgressBar"]


class ProgressBar:
    """A rich progress bar on stderr that appears only once work has taken ``delay`` seconds.

    Parameters
    ----------
    label : str
        What the bar says (the command or the method), followed by the record's stage.
    enabled : bool
        ``False`` (``--quiet``) draws nothing.
    delay : float
        Seconds of work before the bar appears, so that quick commands print nothing.
    """

    def __init__(self, label: str, enabled: bool, delay: float = 1.0):
        self.label = label
        self.enabled = enabled
        self.delay = delay
        self.start = time.monotonic()
        self._bar: Any = None  # a rich Progress, created when the bar first shows
        self._task: Any = None

    def __call__(self, progress: Progress) -> None:
        if not self.enabled:
            return
        if self._bar is None:
            if time.monotonic() - self.start < self.delay:
                return
            from rich.console import Console
            from rich.progress import BarColumn, TextColumn, TimeElapsedColumn
            from rich.progress import Progress as RichProgress

            self._bar = RichProgress(
                TextColumn("{task.description}"),
                BarColumn(),
                TextColumn("{task.completed}/{task.total}"),
                TimeElapsedColumn(),
                console=Console(stderr=True),
                transient=False,
            )
            self._bar.start()
            self._task = self._bar.add_task(self.label, total=progress.total)
        self._bar.update(
            self._task,
            completed=progress.done,
            total=progress.total,
            description=f"{self.label} ({progress.stage})",
        )

    def close(self) -> None:
        """Stop drawing (the bar stays on screen as it was last drawn)."""
        if self._bar is not None:
            self._bar.stop()
            self._bar = None

    def __enter__(self) -> ProgressBar:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
