"""The version of texsyn (layer 0: imported by the report and the front doors).

A literal, read by the build (``pyproject.toml``, ``[tool.setuptools.dynamic]``) and at run
time without ``importlib.metadata``, whose search of the installed distributions costs
about 15 ms of every command's start-up (``docs/performance.md``, "Start-up").
"""

__version__ = "0.2.0"
