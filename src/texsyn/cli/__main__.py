"""``python -m texsyn.cli``: the ``texsyn`` command line."""

from . import run

if __name__ == "__main__":
    run()
