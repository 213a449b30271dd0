"""Lazy package exports (layer 0): a package names what it offers, a submodule loads on first use.

``import texsyn`` must stay cheap (``docs/performance.md``, "Start-up"): the methods, numba,
scipy's submodules and scikit-learn load only when the work needs them. A package lists its
public names and the submodule holding each; :func:`lazy_exports` gives it the module
``__getattr__`` (PEP 562) that imports that submodule when the name is first read and keeps
the value in the package's namespace, so that later reads cost nothing.
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable, Mapping
from typing import Any


def lazy_exports(
    package: str, exports: Mapping[str, str], fallback: Callable[[str], Any] | None = None
) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """The module ``__getattr__`` and ``__dir__`` of a package with lazily loaded names.

    Parameters
    ----------
    package : str
        The package's ``__name__``.
    exports : mapping of str to str
        Each public name and the submodule (relative, without the dot) that defines it.
    fallback : callable, optional
        Called with a name that ``exports`` lacks (deprecated aliases); raises
        ``AttributeError`` itself when the name is unknown.

    Returns
    -------
    (getattr, dir) : the two module-level functions to assign in the package.

    Examples
    --------
    >>> getattr_, dir_ = lazy_exports("json", {"JSONDecoder": "decoder"})
    >>> getattr_("JSONDecoder").__name__
    'JSONDecoder'
    """

    def __getattr__(name: str) -> Any:
        module = exports.get(name)
        if module is None:
            if fallback is not None:
                return fallback(name)
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(f".{module}", package), name)
        setattr(sys.modules[package], name, value)
        return value

    def __dir__() -> list[str]:
        return sorted(set(vars(sys.modules[package])) | set(exports))

    return __getattr__, __dir__
