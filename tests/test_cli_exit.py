"""The end of a ``texsyn`` process (:func:`texsyn.cli.app.exit_process`): Python's exit
without its teardown, and Python's own exit wherever skipping the teardown could lose work.

Each case runs in a new interpreter whose :func:`os._exit` prints "[os._exit]" on stderr first.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

PRELUDE = """
import atexit, os, sys, threading, time
from texsyn.cli.app import exit_process

end_now = os._exit

def noted_exit(status):
    os.write(2, b"[os._exit]")  # not through sys.stderr: no flush of the streams here
    end_now(status)

os._exit = noted_exit
"""


def python_env() -> dict:
    """The environment of the cases: this checkout's texsyn, buffered standard streams."""
    env = dict(os.environ, PYTHONPATH=str(ROOT / "src"))
    env.pop("PYTHONUNBUFFERED", None)
    return env


def run_python(code: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-c", textwrap.dedent(PRELUDE) + textwrap.dedent(code)],
        capture_output=True,
        text=True,
        env=python_env(),
        timeout=60,
    )


def test_status_atexit_functions_and_buffered_output_without_teardown():
    done = run_python(
        """
        sys.stdout.write("buffered")  # a pipe: held in the buffer until flushed
        atexit.register(lambda: sys.stdout.write(" atexit"))
        exit_process(3)
        """
    )
    assert (done.returncode, done.stdout, done.stderr) == (3, "buffered atexit", "[os._exit]")


def test_texsyns_idle_pool_does_not_keep_the_teardown():
    done = run_python(
        """
        from texsyn.ops.linalg import parallel_map, worker_count
        assert parallel_map(abs, range(-3 * max(2, worker_count()), 0))[0] > 0
        assert any(not t.daemon for t in threading.enumerate() if t is not threading.main_thread())
        exit_process(0)
        """
    )
    assert (done.returncode, done.stdout, done.stderr) == (0, "", "[os._exit]")


def test_a_running_thread_is_awaited_by_pythons_own_exit():
    done = run_python(
        """
        def late():
            time.sleep(0.3)
            sys.stdout.write("thread done")
        threading.Thread(target=late).start()
        exit_process(0)
        """
    )
    assert (done.returncode, done.stdout, done.stderr) == (0, "thread done", "")


@pytest.mark.parametrize(
    "setup",
    ["sys.settrace(lambda *a: None)", "sys.setprofile(lambda *a: None)"],
    ids=["tracer", "profiler"],
)
def test_a_tracer_or_profiler_gets_pythons_own_exit(setup):
    done = run_python(f"{setup}\nexit_process(4)\n")
    assert (done.returncode, done.stdout, done.stderr) == (4, "", "")


def test_a_closed_pipe_gets_pythons_own_exit():
    code = 'sys.stdout.write("x" * 100)\ntime.sleep(0.5)\nexit_process(0)\n'
    process = subprocess.Popen(
        [sys.executable, "-c", textwrap.dedent(PRELUDE) + code],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        env=python_env(),
    )
    assert process.stdout is not None and process.stderr is not None
    process.stdout.close()  # the reader leaves while the output waits in the buffer
    err = process.stderr.read().decode()
    assert process.wait(timeout=60) == 120  # Python's status for an output it could not flush
    assert "BrokenPipeError" in err


def test_the_command_line_ends_with_its_status(tmp_path):
    env = python_env()
    listed = subprocess.run(
        [sys.executable, "-m", "texsyn.cli", "methods"], capture_output=True, text=True, env=env, timeout=120
    )
    assert listed.returncode == 0 and "quilting" in listed.stdout, listed.stderr
    command = ["synth", str(tmp_path / "none.png"), "-o", str(tmp_path / "o.png")]
    missing = subprocess.run(
        [sys.executable, "-m", "texsyn.cli", *command],
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
    )
    assert missing.returncode == 2
    assert missing.stderr.count("\n") == 1 and missing.stderr.startswith("texsyn: error:")
    assert list(tmp_path.iterdir()) == []


def test_a_command_started_without_stdout_still_succeeds(tmp_path):
    # ``texsyn synth ... >&-``: Python gives no sys.stdout; the outputs are files
    out = tmp_path / "out.png"
    command = (
        f"exec {sys.executable} -m texsyn.cli synth builtin:gravel -m quilting --size 48x48 -o {out} >&-"
    )
    done = subprocess.run(
        ["sh", "-c", command], capture_output=True, text=True, env=python_env(), timeout=120
    )
    assert done.returncode == 0, done.stderr
    assert "error" not in done.stderr and out.exists()
