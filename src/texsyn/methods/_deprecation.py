"""Deprecation warnings that name the user's line, whatever the front door.

Python shows a :class:`DeprecationWarning` under its default filters only when the warning
is attributed to ``__main__``. A fixed ``stacklevel`` names the user's line for one path
only: the same renamed parameter reaches :meth:`TextureSynthesizer.canonical_params
<texsyn.methods._base.TextureSynthesizer.canonical_params>` from the class constructor,
:func:`texsyn.make_method`, :func:`texsyn.synthesize`, :func:`texsyn.load`..., each at
another depth. :func:`user_stacklevel` walks the stack instead, to the first frame outside
the package (``docs/architecture.md``, "Vocabulary": old names keep working, with a
warning).

The command line (``texsyn.cli``) counts as outside: it is the user's front, and shows
texsyn's warnings itself as one ``texsyn: warning:`` line (:func:`texsyn.cli.main`).
"""

from __future__ import annotations

import os
import sys
import warnings
from typing import Any

from ..errors import InputError

__all__ = ["rename_deprecated", "user_stacklevel", "warn_deprecated"]

#: ``.../texsyn/`` and ``.../texsyn/cli/``, as the interpreter spells module file names
_PACKAGE = os.path.dirname(os.path.dirname(os.path.abspath(__file__))) + os.sep
_FRONT = os.path.join(_PACKAGE, "cli") + os.sep


def _inside(filename: str) -> bool:
    """Whether code of ``filename`` is texsyn's own (the command line excepted)."""
    if filename.startswith("<"):  # "<string>", "<stdin>", "<doctest ...>": the user's
        return False
    path = filename if os.path.isabs(filename) else os.path.abspath(filename)
    return path.startswith(_PACKAGE) and not path.startswith(_FRONT)


def user_stacklevel() -> int:
    """The ``stacklevel`` that names the first frame outside texsyn.

    For a :func:`warnings.warn` called by the caller of this function: 1 is that caller,
    2 its caller, and so on.

    Returns
    -------
    int
        Larger than the stack when every frame is texsyn's (the warning then names
        ``sys``, as for any too large ``stacklevel``).

    Examples
    --------
    >>> user_stacklevel()  # called from a doctest, which is not texsyn's code
    1
    """
    frame = sys._getframe(1)
    level = 1
    while frame is not None and _inside(frame.f_code.co_filename):
        frame = frame.f_back  # type: ignore[assignment]
        level += 1
    return level


def warn_deprecated(message: str, stacklevel: int | None = None) -> None:
    """Issue a :class:`DeprecationWarning` attributed to the user's code.

    Parameters
    ----------
    message : str
    stacklevel : int, optional
        The frame to name, counted from the caller of this function (1 is that caller);
        ``None``, the default, names the first frame outside texsyn (:func:`user_stacklevel`).
    """
    level = user_stacklevel() if stacklevel is None else stacklevel + 1
    warnings.warn(message, DeprecationWarning, stacklevel=level)


def rename_deprecated(
    params: dict[str, Any], renames: dict[str, str], method: str, stacklevel: int | None = None
) -> dict[str, Any]:
    """``params`` with each old name of ``renames`` replaced by its new one, a warning each.

    Parameters
    ----------
    params : dict
    renames : dict of str to str
        Old name to new name (a method's ``deprecated_params``).
    method : str
        The method's name, for the messages.
    stacklevel : int, optional
        As in :func:`warn_deprecated`, counted from the caller of this function.

    Raises
    ------
    InputError
        When a parameter is given under both its old and its new name.

    Examples
    --------
    >>> import warnings
    >>> with warnings.catch_warnings(record=True) as seen:
    ...     warnings.simplefilter("always")
    ...     rename_deprecated({"epsilon": 0.1}, {"epsilon": "tolerance"}, "efros_leung")
    {'tolerance': 0.1}
    >>> str(seen[0].message)
    "parameter 'epsilon' of method 'efros_leung' is deprecated; use 'tolerance'"
    """
    out = dict(params)
    for old, new in renames.items():
        if old in out:
            if new in out:
                raise InputError(
                    f"parameter {old!r} of method {method!r} is the deprecated name of {new!r}; give only {new!r}"
                )
            level = None if stacklevel is None else stacklevel + 1
            warn_deprecated(f"parameter {old!r} of method {method!r} is deprecated; use {new!r}", level)
            out[new] = out.pop(old)
    return out
