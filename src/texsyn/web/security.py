"""Who may talk to the server: the Host, Origin and token checks of every request.

A server on the loopback address is still reachable from any web page the user visits: a
page can send requests to ``http://127.0.0.1:8000`` (cross-site requests), and a name the
attacker controls can be made to resolve to 127.0.0.1 (DNS rebinding), which the browser
then treats as the attacker's own origin. So every request must

1. name this server in its ``Host`` header (rebinding sends the attacker's name);
2. come from this server's own pages when a browser says where it comes from (``Origin``);
3. carry this launch's token (``?token=`` or ``X-Texsyn-Token``), which only the user who
   started the server has (``docs/web.md``, "Safety").

The package's static files (the page's script and style, which hold nothing of the user's)
need no token, but the Host check applies to them too.
"""

from __future__ import annotations

import secrets
from collections.abc import Callable

from starlette.responses import JSONResponse, Response
from starlette.types import ASGIApp, Receive, Scope, Send

from .settings import ServerSettings

__all__ = ["RequestGuard", "SECURITY_HEADERS", "refusal"]

#: headers on every response: no framing by other sites, no token in a Referer, no sniffing
SECURITY_HEADERS = {
    "x-content-type-options": "nosniff",
    "referrer-policy": "no-referrer",
    "x-frame-options": "SAMEORIGIN",
    "cross-origin-resource-policy": "same-origin",
    "cache-control": "no-store",
}

#: the page's own policy: scripts and styles from this server only
PAGE_POLICY = (
    "default-src 'self'; img-src 'self' data: blob:; media-src 'self' blob:; "
    "frame-src 'self'; style-src 'self'; script-src 'self'; connect-src 'self'; "
    "base-uri 'none'; form-action 'none'; frame-ancestors 'self'"
)


def refusal(status: int, message: str) -> Response:
    """A JSON ``{"error": message}`` response: every refusal of the server looks like this."""
    return JSONResponse({"error": message}, status_code=status, headers=SECURITY_HEADERS)


class RequestGuard:
    """ASGI middleware: refuse a request with a wrong Host, a foreign Origin or no token.

    Parameters
    ----------
    app : ASGI application
    settings : ServerSettings
    public_prefixes : tuple of str
        Paths that need no token (the static files).
    """

    def __init__(
        self,
        app: ASGIApp,
        settings: ServerSettings,
        public_prefixes: tuple[str, ...] = ("/static/", "/favicon.ico"),
    ):
        self.app = app
        self.settings = settings
        self.public_prefixes = public_prefixes
        self.allowed_hosts = settings.allowed_hosts
        self.allowed_origins = frozenset(f"http://{host}" for host in self.allowed_hosts)
        #: called by ``texsyn serve`` as the server stops, before it waits for open requests:
        #: the application ends its event streams (set by :func:`texsyn.web.app.create_app`)
        self.end_streams: Callable[[], None] = lambda: None

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] not in ("http", "websocket"):
            await self.app(scope, receive, send)
            return
        problem = self.check(scope)
        if problem is not None:
            status, message = problem
            await refusal(status, message)(scope, receive, send)
            return

        async def send_with_headers(message) -> None:
            if message["type"] == "http.response.start":
                headers = list(message.get("headers", []))
                present = {name.lower() for name, _ in headers}
                for name, value in SECURITY_HEADERS.items():
                    if name.encode() not in present:
                        headers.append((name.encode(), value.encode()))
                if scope.get("path") == "/" and b"content-security-policy" not in present:
                    headers.append((b"content-security-policy", PAGE_POLICY.encode()))
                message = {**message, "headers": headers}
            await send(message)

        await self.app(scope, receive, send_with_headers)

    def check(self, scope: Scope) -> tuple[int, str] | None:
        """``(status, message)`` when the request must be refused, ``None`` when it may pass."""
        headers = {
            name.decode("latin-1").lower(): value.decode("latin-1") for name, value in scope["headers"]
        }
        host = headers.get("host", "").strip().lower()
        if host not in self.allowed_hosts:
            return 421, (
                "wrong Host header: this texsyn server answers only requests addressed to "
                + ", ".join(sorted(self.allowed_hosts))
            )
        origin = headers.get("origin")
        if origin is not None and origin.strip().lower() not in self.allowed_origins:
            return 403, "cross-site request refused: the Origin is not this texsyn server's page"
        path = scope.get("path", "")
        if any(path.startswith(prefix) for prefix in self.public_prefixes):
            return None
        token = headers.get("x-texsyn-token") or _query_token(scope.get("query_string", b""))
        if not token or not secrets.compare_digest(token.encode(), self.settings.token.encode()):
            return (
                401,
                "missing or wrong token: open the address `texsyn serve` printed (it ends in ?token=...)",
            )
        return None


def _query_token(query: bytes) -> str | None:
    """The ``token`` parameter of a query string (its first value), undecoded beyond URL form."""
    from urllib.parse import parse_qs

    values = parse_qs(query.decode("latin-1"), keep_blank_values=True).get("token")
    return values[0] if values else None
