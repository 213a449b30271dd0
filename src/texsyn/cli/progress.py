"""The progress display of the command line: the one adapter from texsyn's progress records.

Every command passes a :class:`ProgressBar` as the ``callback`` of the API it calls; it
receives the :class:`~texsyn.ops.progress.Progress` records every method reports
(``docs/architecture.md``, "Progress") and draws them as a rich bar on stderr, or, with
``texsyn --progress json``, writes them as JSON lines for another program (``texsyn serve``
reads them; ``docs/cli.md``).
"""

from __future__ import annotations

import json
import sys
import time
from collections.abc import Callable
from typing import Any

import click

from ..ops.progress import Progress
from .common import State

#: seconds between two JSON progress lines of the same stage (a new stage and the last
#: record of a stage are always written)
JSON_INTERVAL = 0.1


def progress_format() -> str:
    """``"bar"`` or ``"json"``: what ``texsyn --progress`` asked for in this run."""
    ctx = click.get_current_context(silent=True)
    state = ctx.find_object(State) if ctx is not None else None
    return state.progress if state is not None else "bar"


__all__ = ["ProgressBar"]


class ProgressBar:
    """A rich progress bar on stderr that appears only once work has taken ``delay`` seconds.

    It shows the label and stage, the bar, ``done/total``, the time elapsed since the bar
    was made (the command's start) and the time remaining (ETA) of the current stage,
    estimated by rich from the recent speed. A new stage (another ``stage`` name, e.g. from
    fitting to frames) starts a new estimate, so units of different stages are never mixed.

    Parameters
    ----------
    label : str
        What the bar says (the command or the method), followed by the record's stage.
    enabled : bool
        ``False`` (``--quiet``) draws nothing.
    delay : float
        Seconds of work before the bar appears, so that quick commands print nothing.
    clock : callable, optional
        Seconds of a monotonic clock, for the delay, the elapsed time and the ETA
        (``time.monotonic`` by default; tests pass a fake one).
    """

    #: the bar and the JSON lines show counts, never the intermediate images
    #: (:attr:`texsyn.ops.progress.Reporter.wants_images`)
    wants_images = False

    def __init__(
        self, label: str, enabled: bool, delay: float = 1.0, clock: Callable[[], float] = time.monotonic
    ):
        self.label = label
        self.enabled = enabled
        self.delay = delay
        self.clock = clock
        self.start = clock()
        self._bar: Any = None  # a rich Progress, created when the bar first shows
        self._task: Any = None
        self._stage: str | None = None
        self._json = progress_format() == "json"
        self._last_line = -float("inf")

    def __call__(self, progress: Progress) -> None:
        if not self.enabled:
            return
        if self._json:
            self._write_json(progress)
            return
        description = f"{self.label} ({progress.stage})"
        if self._bar is None:
            if self.clock() - self.start < self.delay:
                return
            from rich.console import Console
            from rich.progress import BarColumn, TextColumn, TimeElapsedColumn, TimeRemainingColumn
            from rich.progress import Progress as RichProgress

            self._bar = RichProgress(
                TextColumn("{task.description}"),
                BarColumn(),
                TextColumn("{task.completed}/{task.total}"),
                TimeElapsedColumn(),
                TextColumn("ETA"),
                TimeRemainingColumn(),
                console=Console(stderr=True),
                transient=False,
                get_time=self.clock,
            )
            self._bar.start()
            self._task = self._bar.add_task(description, total=progress.total, completed=progress.done)
            self._stage = progress.stage
            self._rich_task().start_time = self.start  # elapsed counts from the command's start
        elif progress.stage != self._stage:
            # a new stage counts other units: forget the old speed (the ETA), keep the elapsed time
            self._bar.reset(
                self._task, total=progress.total, completed=progress.done, description=description
            )
            self._rich_task().start_time = self.start
            self._stage = progress.stage
        self._bar.update(self._task, completed=progress.done, total=progress.total, description=description)

    def _write_json(self, progress: Progress) -> None:
        """One line ``{"progress": {"label", "stage", "done", "total", "elapsed"}}`` on stderr."""
        now = self.clock()
        new_stage = progress.stage != self._stage
        if not new_stage and progress.done < progress.total and now - self._last_line < JSON_INTERVAL:
            return
        self._stage, self._last_line = progress.stage, now
        record = {
            "label": self.label,
            "stage": progress.stage,
            "done": progress.done,
            "total": progress.total,
            "elapsed": round(now - self.start, 3),
        }
        sys.stderr.write(json.dumps({"progress": record}) + "\n")
        sys.stderr.flush()

    def _rich_task(self) -> Any:
        """The rich task of the bar (a ``rich.progress.Task``)."""
        return next(task for task in self._bar.tasks if task.id == self._task)

    def close(self) -> None:
        """Stop drawing (the bar stays on screen as it was last drawn)."""
        if self._bar is not None:
            self._bar.stop()
            self._bar = None

    def __enter__(self) -> ProgressBar:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
