"""The ``texsyn`` command line. It only calls the public API; options come from the registry.

``texsyn.cli:main`` is the console script's entry point (``docs/cli.md``). The parts:

- :mod:`~texsyn.cli.app`: the ``texsyn`` group, :func:`main`, exit statuses and the one-line
  messages (``docs/errors.md``);
- :mod:`~texsyn.cli.options`: ``--size WIDTHxHEIGHT``, numbers, and method parameters from
  the registry;
- :mod:`~texsyn.cli.common`: the steps every command shares (outputs claimed before any
  work, the memory check, the seed, the JSON sidecar);
- :mod:`~texsyn.cli.progress`: the progress display;
- the commands: :mod:`~texsyn.cli.synthesis` (``synth``, ``modify``, ``animate``),
  :mod:`~texsyn.cli.comparison` (``compare``) and :mod:`~texsyn.cli.listing` (``methods``).
"""

from __future__ import annotations

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
)
from .comparison import compare
from .listing import list_methods
from .options import MAX_SIDE
from .synthesis import animate, modify, synth

for _command in (synth, modify, animate, compare, list_methods):
    cli.add_command(_command)
del _command

__all__ = [
    "EXIT_BAD_INPUT",
    "EXIT_BROKEN_PIPE",
    "EXIT_FAILURE",
    "EXIT_INTERRUPTED",
    "EXIT_OK",
    "EXIT_TERMINATED",
    "MAX_SIDE",
    "Terminated",
    "cli",
    "main",
]
