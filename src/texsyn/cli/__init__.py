"""The ``texsyn`` command line. It only calls the public API; options come from the registry.

``texsyn.cli:run`` is the console script's entry point (``docs/cli.md``): :func:`main`, which
returns the exit status, then the end of the process. The parts:

- :mod:`~texsyn.cli.app`: the ``texsyn`` group, :func:`main`, exit statuses and the one-line
  messages (``docs/errors.md``);
- :mod:`~texsyn.cli.options`: ``--size WIDTHxHEIGHT``, numbers, and method parameters from
  the registry;
- :mod:`~texsyn.cli.common`: the steps every command shares (outputs claimed before any
  work, the memory check, the seed, the JSON sidecar);
- :mod:`~texsyn.cli.progress`: the progress display;
- the commands, each loaded when it runs (:class:`~texsyn.cli.app.LazyCommands`):
  :mod:`~texsyn.cli.synthesis` (``synth``), :mod:`~texsyn.cli.modification` (``modify``),
  :mod:`~texsyn.cli.animation` (``animate``), :mod:`~texsyn.cli.comparison` (``compare``),
  :mod:`~texsyn.cli.batch` (``batch``) and :mod:`~texsyn.cli.listing` (``methods``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .._lazy import lazy_exports
from .app import (
    EXIT_BAD_INPUT,
    EXIT_BROKEN_PIPE,
    EXIT_FAILURE,
    EXIT_INTERRUPTED,
    EXIT_OK,
    EXIT_TERMINATED,
    Terminated,
    cli,
    main,
    run,
)

if TYPE_CHECKING:  # the names for type checkers; at run time ``__getattr__`` loads them
    from .animation import animate
    from .batch import batch
    from .comparison import compare
    from .listing import list_methods
    from .modification import modify
    from .options import MAX_SIDE
    from .synthesis import synth

# the commands load when run (``app.LazyCommands``); their functions on first use here
__getattr__, __dir__ = lazy_exports(
    __name__,
    {
        "MAX_SIDE": "options",
        "animate": "animation",
        "batch": "batch",
        "compare": "comparison",
        "list_methods": "listing",
        "modify": "modification",
        "synth": "synthesis",
    },
)

__all__ = [
    "EXIT_BAD_INPUT",
    "EXIT_BROKEN_PIPE",
    "EXIT_FAILURE",
    "EXIT_INTERRUPTED",
    "EXIT_OK",
    "EXIT_TERMINATED",
    "MAX_SIDE",
    "Terminated",
    "animate",
    "batch",
    "cli",
    "compare",
    "list_methods",
    "main",
    "modify",
    "run",
    "synth",
]
