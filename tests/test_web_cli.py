"""``texsyn serve`` as a command (issue 21): the address it prints, the warning off loopback,
Ctrl-C, and a temporary folder that leaves nothing behind."""

from __future__ import annotations

import contextlib
import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

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


def children_of(pid: int) -> set[int]:
    """Processes whose parent is ``pid`` (from /proc)."""
    found = set()
    for stat in Path("/proc").glob("[0-9]*/stat"):
        with contextlib.suppress(OSError, IndexError, ValueError):
            fields = stat.read_text().rsplit(")", 1)[1].split()
            if int(fields[1]) == pid and fields[0] != "Z":
                found.add(int(stat.parent.name))
    return found


def alive(pid: int) -> bool:
    with contextlib.suppress(OSError, IndexError):
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    return False


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads /proc")
def test_ctrl_c_stops_the_server_and_its_job_while_a_page_watches_the_job(tmp_path):
    process, url, _ = start(tmp_path)
    token = url.split("token=")[1]
    base = url.split("/?")[0]
    watched = threading.Event()

    def watch(job_id: str) -> None:  # the page's event stream stays open while the job runs
        with contextlib.suppress(httpx.HTTPError):
            with httpx.stream("GET", f"{base}/api/jobs/{job_id}/events?token={token}", timeout=120) as r:
                for _ in r.iter_lines():
                    watched.set()

    try:
        long = {"exemplar": "builtin:brick", "method": "efros_leung", "size": [400, 400], "seed": 1}
        job = httpx.post(f"{base}/api/jobs?token={token}", json=long, timeout=30).json()
        threading.Thread(target=watch, args=(job["id"],), daemon=True).start()
        deadline = time.monotonic() + 30
        while not (watched.is_set() and children_of(process.pid)) and time.monotonic() < deadline:
            time.sleep(0.05)
        workers = children_of(process.pid)
        assert workers and watched.is_set()
        started = time.monotonic()
        process.send_signal(signal.SIGINT)
        process.wait(timeout=20)
        assert time.monotonic() - started < 10  # not when the job ends
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
            for pid in children_of(process.pid) | locals().get("workers", set()):
                with contextlib.suppress(OSError):
                    os.killpg(pid, signal.SIGKILL)  # each job runs in a session of its own
    assert process.returncode == 130
    deadline = time.monotonic() + 5
    while any(alive(pid) for pid in workers) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not any(alive(pid) for pid in workers)  # the job's process went with the server
    assert not list(tmp_path.iterdir())


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
