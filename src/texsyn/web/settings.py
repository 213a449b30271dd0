"""What one launch of ``texsyn serve`` allows: address, token, pool, limits (``docs/web.md``)."""

from __future__ import annotations

import ipaddress
import os
import secrets
import socket
from dataclasses import dataclass, field

__all__ = ["LOOPBACK_NAMES", "WILDCARD_ADDRESSES", "ServerSettings", "is_loopback", "machine_names"]

#: host names that always mean this machine
LOOPBACK_NAMES = ("127.0.0.1", "localhost", "[::1]", "::1")
#: addresses that listen on every interface
WILDCARD_ADDRESSES = ("0.0.0.0", "::", "[::]")


def machine_names() -> set[str]:
    """This machine's host name, full name and addresses: how other machines may name it."""
    names = set()
    try:
        hostname = socket.gethostname()
        names |= {hostname.lower(), socket.getfqdn().lower()}
        names |= {str(info[4][0]).lower() for info in socket.getaddrinfo(hostname, None)}
    except OSError:  # no name service: the loopback names remain
        pass
    return names


def is_loopback(host: str) -> bool:
    """Whether ``host`` (a name or an address) is reachable from this machine only."""
    name = host.strip("[]").lower()
    if name == "localhost":
        return True
    try:
        return ipaddress.ip_address(name).is_loopback
    except ValueError:
        return False


@dataclass(frozen=True)
class ServerSettings:
    """The settings of one server launch.

    Attributes
    ----------
    host, port : str, int
        Where uvicorn listens; requests must name this address (or a loopback name) in their
        ``Host`` header, and a browser's ``Origin`` must be that address too.
    token : str
        Secret of this launch: every request but the static files must carry it (``?token=``
        or the ``X-Texsyn-Token`` header). A new random one per launch by default.
    workers : int
        Jobs run at once (one process each); the others wait in a queue.
    queue_limit : int
        Jobs waiting at most; more is refused with a clear message.
    max_upload_bytes : int
        Largest exemplar file accepted (20 MB by default), checked while it arrives.
    max_pixels : int
        Largest exemplar in pixels, checked from its header before decoding.
    max_side : int
        Largest output side in pixels.
    job_timeout : float
        Seconds a job may run before it is stopped.
    extra_hosts : tuple of str
        More names the ``Host`` header may give (``texsyn serve --allow-host``), e.g. the
        name under which other machines reach a server bound to every interface.
    """

    host: str = "127.0.0.1"
    port: int = 8000
    token: str = field(default_factory=lambda: secrets.token_urlsafe(24))
    workers: int = field(default_factory=lambda: os.cpu_count() or 1)
    queue_limit: int = 16
    max_upload_bytes: int = 20 * 1000 * 1000
    max_pixels: int = 16_000_000
    max_side: int = 4096
    job_timeout: float = 600.0
    extra_hosts: tuple[str, ...] = ()

    @property
    def allowed_hosts(self) -> frozenset[str]:
        """``Host`` header values this server answers (lower case, with the port)."""
        names = {self.host.lower(), *(name.lower() for name in self.extra_hosts)}
        if is_loopback(self.host) or self.host in WILDCARD_ADDRESSES:
            names |= set(LOOPBACK_NAMES)
        if self.host in WILDCARD_ADDRESSES:
            names |= machine_names()
        out = set()
        for name in names:
            bracketed = f"[{name}]" if ":" in name and not name.startswith("[") else name
            out.add(f"{bracketed}:{self.port}")
        return frozenset(out)

    @property
    def url(self) -> str:
        """The address of the page, with the token (what ``texsyn serve`` prints and opens)."""
        host = f"[{self.host}]" if ":" in self.host and not self.host.startswith("[") else self.host
        if self.host in WILDCARD_ADDRESSES:
            host = "127.0.0.1"
        return f"http://{host}:{self.port}/?token={self.token}"
