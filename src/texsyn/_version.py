"""The installed version of texsyn (layer 0: imported by the report and the front doors)."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("texsyn")
except PackageNotFoundError:  # pragma: no cover - running from a source tree
    __version__ = "0.0.0+unknown"
