"""A real ``texsyn serve`` server for the web tests: uvicorn in a thread, on a free loopback port."""

from __future__ import annotations

import contextlib
import socket
import threading
import time
from dataclasses import dataclass, replace
from pathlib import Path

import httpx
import uvicorn

from texsyn.web import ServerSettings, create_app


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


@dataclass
class LiveServer:
    """A running server: its settings, its folder, and an httpx client that sends the token."""

    settings: ServerSettings
    folder: Path
    server: uvicorn.Server
    thread: threading.Thread

    @property
    def base(self) -> str:
        return f"http://127.0.0.1:{self.settings.port}"

    @property
    def page(self) -> str:
        return self.settings.url

    def client(self, **kwargs) -> httpx.Client:
        headers = {"X-Texsyn-Token": self.settings.token}
        headers.update(kwargs.pop("headers", {}))
        return httpx.Client(base_url=self.base, headers=headers, timeout=60, **kwargs)

    def stop(self) -> None:
        self.server.should_exit = True
        self.thread.join(timeout=15)


@contextlib.contextmanager
def live_server(folder: Path, **settings):
    """Start a server with ``settings`` (ServerSettings fields) writing into ``folder``."""
    chosen = replace(ServerSettings(), port=free_port(), **settings)
    config = uvicorn.Config(
        create_app(chosen, folder), host="127.0.0.1", port=chosen.port, log_level="warning"
    )
    server = uvicorn.Server(config)
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    deadline = time.monotonic() + 30
    while not server.started:
        if time.monotonic() > deadline or not thread.is_alive():
            raise RuntimeError("the test server did not start")
        time.sleep(0.02)
    live = LiveServer(chosen, Path(folder), server, thread)
    try:
        yield live
    finally:
        live.stop()


def wait_for(
    client: httpx.Client, job_id: str, timeout: float = 60.0, states=("done", "failed", "cancelled")
) -> dict:
    """Poll a job until it reaches one of ``states``; its last public record."""
    deadline = time.monotonic() + timeout
    while True:
        record = client.get(f"/api/jobs/{job_id}").json()
        if record["state"] in states:
            return record
        if time.monotonic() > deadline:
            raise AssertionError(f"job {job_id} still {record['state']} after {timeout} s: {record}")
        time.sleep(0.05)
