"""``texsyn serve``: a local web page to try every method on one's own image (``docs/web.md``).

The page (plain HTML, CSS and JavaScript under ``static/``, no build step) uploads an
exemplar or picks a built-in one, builds its form from the method registry's parameter
specs, and runs jobs through the command line itself, one process each, in a bounded pool
(:mod:`texsyn.web.jobs`), with live progress, cancel, metrics, downloads and the equivalent
command line. Loopback by default; every request is checked for its Host, its Origin and
the launch's token (:mod:`texsyn.web.security`).

Importing this package needs the ``web`` extra (FastAPI, uvicorn); ``import texsyn`` never
imports it.
"""

from __future__ import annotations

from .settings import ServerSettings, is_loopback

__all__ = ["ServerSettings", "create_app", "is_loopback"]


def create_app(settings: ServerSettings | None = None, folder=None):
    """The ASGI application (:func:`texsyn.web.app.create_app`); FastAPI loads on this call."""
    from .app import create_app as make

    return make(settings, folder)
