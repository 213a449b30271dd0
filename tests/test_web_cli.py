"""``texsyn serve`` as a command (issue 21): the address it prints, the warning off loopback,
Ctrl-C, and a temporary folder that leaves nothing behind."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time

import httpx
import pytest

pytest.importorskip("fastapi")
pytest.importorskip("uvicorn")

from texsyn.web import ServerSettings, is_loopback
from web_utils import free_port


def start(tmp_path, *args):
    env = dict(os.environ, TMPDIR=str(tmp_path))
    port = free_port()
    process = subprocess.Popen(
        [sys.executable, "-m", "texsyn.cli", "serve", "--port", str(port), *args],
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    lines = []
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        line = process.stderr.readline()
        lines.append(line)
        if "serving on" in line:
            break
    url = re.search(r"http://\S+", lines[-1]).group(0)
    for _ in range(200):  # until uvicorn listens
        try:
            httpx.get(url, timeout=2)
            break
        except httpx.TransportError:
            time.sleep(0.05)
    return process, url, lines


@pytest.mark.parametrize("stop, status", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_serve_prints_a_token_address_serves_and_leaves_nothing_on_a_signal(tmp_path, stop, status):
    process, url, lines = start(tmp_path)
    try:
        assert url.startswith("http://127.0.0.1:") and "?token=" in url
        assert not any("warning" in line for line in lines)
        page = httpx.get(url, timeout=10)
        assert page.status_code == 200 and "<title>texsyn</title>" in page.text
        assert httpx.get(url.split("?")[0], timeout=10).status_code == 401
        assert any(p.name.startswith("texsyn-serve-") for p in tmp_path.iterdir())
    finally:
        process.send_signal(stop)
        process.wait(timeout=30)
    assert process.returncode == status
    assert not list(tmp_path.iterdir())  # the uploads and results went with the server


def test_serve_warns_when_it_listens_beyond_loopback(tmp_path):
    process, url, lines = start(tmp_path, "--host", "0.0.0.0")
    try:
        assert any("warning: listening on 0.0.0.0, not loopback" in line for line in lines)
    finally:
        process.send_signal(signal.SIGINT)
        process.wait(timeout=30)


def test_allowed_hosts_follow_the_address():
    local = ServerSettings(host="127.0.0.1", port=8000)
    assert {"127.0.0.1:8000", "localhost:8000", "[::1]:8000"} <= local.allowed_hosts
    assert "evil.example:8000" not in local.allowed_hosts
    lan = ServerSettings(host="192.168.1.7", port=9000)
    assert lan.allowed_hosts == {"192.168.1.7:9000"}
    every = ServerSettings(host="0.0.0.0", port=9000, extra_hosts=("texsyn.lan",))
    assert {"127.0.0.1:9000", "texsyn.lan:9000"} <= every.allowed_hosts
    assert every.url.startswith("http://127.0.0.1:9000/?token=")
    assert is_loopback("127.0.0.2") and is_loopback("::1") and not is_loopback("0.0.0.0")
    assert ServerSettings().token != ServerSettings().token  # a new token per launch
