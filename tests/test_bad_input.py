"""A bad-input corpus through the command line: exit codes, one line, nothing written.

Every case runs ``texsyn.cli.main`` in-process (signals run ``texsyn`` in a subprocess) and
checks: the exit status (2 for the user's mistakes, 1 for failures that are not, 130/143 for
SIGINT/SIGTERM), exactly one line on stderr starting ``texsyn:``, no traceback, and that the
folder is unchanged (no file created, no existing file touched: same bytes and mtime, no
temporary left).
"""

from __future__ import annotations

import contextlib
import errno
import io
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from PIL import Image

import texsyn
from texsyn.cli import main
from texsyn.io import streaming, writing
from texsyn.methods.random_phase import RandomPhase

FAST = ["-m", "random_phase", "--size", "16x16", "-q"]


def snapshot(folder: Path) -> dict:
    """Every entry under ``folder`` (hidden ones too) with its bytes and mtime."""
    out = {}
    for path in sorted(folder.rglob("*")):
        rel = str(path.relative_to(folder))
        if path.is_symlink():
            out[rel] = ("link", os.readlink(path))
        elif path.is_dir():
            out[rel] = ("dir",)
        else:
            st_ = path.stat()
            out[rel] = (path.read_bytes(), st_.st_mtime_ns)
    return out


def run(capsys, *args) -> tuple[int, str]:
    code = main([str(a) for a in args])
    captured = capsys.readouterr()
    return code, captured.err


def check_one_line(
    code: int, err: str, status: int, message: str | None = None, prefix: str = "texsyn: error: "
):
    assert code == status, err
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith(prefix), err
    if message is not None:
        assert message in lines[0], err


@pytest.fixture
def work(tmp_path, monkeypatch):
    """A folder (the working directory) with an exemplar, existing outputs, links and odd files."""
    monkeypatch.chdir(tmp_path)
    brick = texsyn.data.exemplar("brick", size=32)
    Image.fromarray((brick * 255).astype(np.uint8)).save(tmp_path / "ex.png")
    Image.fromarray((brick * 255).astype(np.uint8)).convert("RGB").save(tmp_path / "flow.png")
    (tmp_path / "existing.png").write_bytes(b"an earlier result")
    (tmp_path / "existing.gif").write_bytes(b"an earlier video")
    (tmp_path / "side.png.json").write_text("{}")
    (tmp_path / "old.json").write_text("{}")
    (tmp_path / "link.png").symlink_to("ex.png")
    os.link(tmp_path / "ex.png", tmp_path / "hard.png")
    (tmp_path / "truncated.ppm").write_bytes(b"P6 4 4")
    (tmp_path / "adir").mkdir()
    (tmp_path / "adir.png").mkdir()
    (tmp_path / "frames").mkdir()
    Image.fromarray((brick * 255).astype(np.uint8)).save(tmp_path / "frames" / "frame_00000.png")
    (tmp_path / "notes").mkdir()
    (tmp_path / "notes" / "todo.txt").write_text("keep me")
    np.save(tmp_path / "nan_flow.npy", np.full((8, 8, 2), np.nan))
    (tmp_path / "in.png.json").write_text("not an image")
    return tmp_path


# ---------------------------------------------------------------------------- the corpus
CASES = [
    # an output that names an input or another output: refused whatever --overwrite says
    ("output is the exemplar", ["synth", "ex.png", "-o", "ex.png"], "is the exemplar"),
    ("output is ./exemplar", ["synth", "ex.png", "-o", "./ex.png", "--overwrite"], "is the exemplar"),
    (
        "output is a symlink to the exemplar",
        ["synth", "ex.png", "-o", "link.png", "--overwrite"],
        "is the exemplar",
    ),
    (
        "output is a hard link to the exemplar",
        ["synth", "ex.png", "-o", "hard.png", "--overwrite"],
        "is the exemplar",
    ),
    (
        "source map is the output",
        ["synth", "ex.png", "-o", "o.png", "--source-map", "o.png"],
        "name the same file",
    ),
    (
        "source map is the exemplar",
        ["synth", "ex.png", "-o", "o.png", "--source-map", "ex.png", "--overwrite"],
        "is the exemplar",
    ),
    ("sidecar is the exemplar", ["synth", "in.png.json", "-o", "in.png", "--overwrite"], "is the exemplar"),
    (
        "magnitudes is INPUT",
        ["modify", "ex.png", "-e", "builtin:brick", "-o", "m.png", "--magnitudes", "ex.png", "--overwrite"],
        "is the INPUT",
    ),
    (
        "modify output is the exemplar",
        ["modify", "builtin:gravel", "-e", "ex.png", "-o", "ex.png", "--overwrite"],
        "is the exemplar",
    ),
    (
        "modify source map is the magnitudes",
        [
            "modify",
            "ex.png",
            "-e",
            "builtin:brick",
            "-o",
            "m.png",
            "--magnitudes",
            "x.npy",
            "--source-map",
            "./x.npy",
        ],
        "name the same file",
    ),
    (
        "output is the flow file",
        ["synth", "-m", "grouplets", "--flow", "flow.png", "-o", "flow.png", "--overwrite"],
        "is the flow file",
    ),
    (
        "frame folder holds the exemplar",
        ["animate", "frames/frame_00000.png", "-o", "frames", "--overwrite"],
        "folder of the exemplar",
    ),
    ("compare report with an image name", ["compare", "ex.png", "-o", "ex.png"], "unsupported file type"),
    # existing outputs are kept without --overwrite, for every command
    ("synth existing output", ["synth", "-o", "existing.png", *FAST], "already exists"),
    ("synth existing sidecar", ["synth", "-o", "side.png", *FAST], "already exists"),
    (
        "synth existing source map",
        ["synth", "ex.png", "-o", "new.png", "--source-map", "existing.png", "-p", "patch_size=8", "-q"],
        "already exists",
    ),
    (
        "modify existing output",
        ["modify", "ex.png", "-e", "builtin:brick", "-o", "existing.png", "-q"],
        "already exists",
    ),
    ("animate existing video", ["animate", "-o", "existing.gif", "--frames", "2", "-q"], "already exists"),
    ("animate existing frame folder", ["animate", "-o", "frames", "--frames", "2", "-q"], "already exists"),
    (
        "animate over a folder of other files",
        ["animate", "-o", "notes", "--frames", "2", "-q", "--overwrite"],
        "other than frame",
    ),
    ("compare existing sidecar", ["compare", "-o", "old.html", "-m", "random_phase", "-q"], "already exists"),
    # output folders
    ("missing folder", ["synth", "-o", "nowhere/o.png", *FAST], "does not exist"),
    ("animate missing folder", ["animate", "-o", "nowhere/a.gif", "-q"], "does not exist"),
    ("output is a folder", ["synth", "-o", "adir.png", *FAST], "adir.png"),
    ("unsupported output type", ["synth", "-o", "o.xyz", *FAST], "unsupported file type"),
    ("output without a name", ["synth", "-o", "", *FAST], "needs a file or folder name"),
    ("frames into the working folder", ["animate", "-o", ".", "-q"], "needs a file or folder name"),
    # option values
    ("scale inf", ["synth", "-o", "o.png", "--scale", "inf"], "finite"),
    ("scale nan", ["synth", "-o", "o.png", "--scale", "nan"], "finite"),
    ("scale -1", ["synth", "-o", "o.png", "--scale", "-1"], "--scale"),
    ("scale 0", ["synth", "-o", "o.png", "--scale", "0"], "--scale"),
    ("scale too small", ["synth", "-o", "o.png", "--scale", "1e-9"], "must be in [1, "),
    ("scale too large", ["synth", "-o", "o.png", "--scale", "1e300"], "--scale"),
    ("fps nan", ["animate", "-o", "a.gif", "--fps", "nan", "-q"], "finite"),
    ("fps inf", ["animate", "-o", "a.gif", "--fps", "inf", "-q"], "finite"),
    ("fps 0", ["animate", "-o", "a.gif", "--fps", "0", "-q"], "--fps"),
    ("size 0x5", ["synth", "-o", "o.png", "--size", "0x5"], "at least 1x1"),
    ("size abc", ["synth", "-o", "o.png", "--size", "abc"], "WIDTHxHEIGHT"),
    ("size -5x5", ["synth", "-o", "o.png", "--size", "-5x5"], "WIDTHxHEIGHT"),
    ("size 1e3x10", ["synth", "-o", "o.png", "--size", "1e3x10"], "WIDTHxHEIGHT"),
    ("size huge", ["synth", "-o", "o.png", "--size", "99999999x99999999"], "at most"),
    ("size too many digits", ["synth", "-o", "o.png", "--size", "9" * 5000 + "x1"], "at most"),
    ("seed -1", ["synth", "-o", "o.png", "--seed", "-1"], "--seed"),
    ("seed 2**64", ["synth", "-o", "o.png", "--seed", str(2**64)], "--seed"),
    ("frames 0", ["animate", "-o", "a.gif", "--frames", "0"], "--frames"),
    ("loop not below frames", ["animate", "-o", "a.gif", "--frames", "3", "--loop", "3"], "--loop"),
    ("ratio nan", ["modify", "ex.png", "-e", "builtin:brick", "-o", "m.png", "-r", "nan"], "finite"),
    ("viscosity inf", ["animate", "-o", "a.gif", "--viscosity", "inf"], "finite"),
    ("patch_size nan", ["synth", "-o", "o.png", "-p", "patch_size=nan"], "patch_size"),
    ("tolerance inf", ["synth", "-o", "o.png", "-p", "tolerance=inf"], "tolerance"),
    (
        "tuple parameter with nan",
        ["modify", "ex.png", "-e", "builtin:brick", "-o", "m.png", "-p", "sigma=0,nan"],
        "sigma",
    ),
    (
        "flow constant:inf",
        ["synth", "-m", "grouplets", "-p", "flow=constant:inf", "-o", "o.png", "--size", "16x16", "-q"],
        "constant:ANGLE",
    ),
    (
        "flow constant:abc",
        ["synth", "-m", "grouplets", "-p", "flow=constant:abc", "-o", "o.png", "--size", "16x16", "-q"],
        "constant:ANGLE",
    ),
    (
        "flow file with nan",
        ["synth", "-m", "grouplets", "--flow", "nan_flow.npy", "-o", "o.png", "-q"],
        "NaN",
    ),
    ("unknown method", ["synth", "-m", "nope", "-o", "o.png"], "unknown method 'nope'"),
    ("unknown command", ["frobnicate"], "frobnicate"),
    # inputs
    ("missing exemplar", ["synth", "missing.png", "-o", "o.png"], "missing.png"),
    ("truncated PNM header", ["synth", "truncated.ppm", "-o", "o.png", "-q"], "truncated.ppm"),
    ("folder as exemplar", ["synth", "adir", "-o", "o.png", "-q"], "adir"),
    ("unknown builtin", ["synth", "builtin:marble", "-o", "o.png", "-q"], "marble"),
]


@pytest.mark.parametrize("label, args, message", CASES, ids=[c[0] for c in CASES])
def test_bad_input_exits_2_with_one_line_and_writes_nothing(work, capsys, label, args, message):
    before = snapshot(work)
    start = time.monotonic()
    code, err = run(capsys, *args)
    assert time.monotonic() - start < 5
    check_one_line(code, err, 2, message)
    assert snapshot(work) == before


def test_memory_limit_that_is_not_a_number(work, capsys, monkeypatch):
    monkeypatch.setenv("TEXSYN_MEMORY_LIMIT", "1e400")
    before = snapshot(work)
    code, err = run(capsys, "synth", "-o", "o.png", *FAST)
    check_one_line(code, err, 2, "TEXSYN_MEMORY_LIMIT")
    assert snapshot(work) == before


def test_read_only_folder_is_refused_before_any_work(work, capsys, monkeypatch):
    ro = work / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    if os.access(ro, os.W_OK):  # root ignores permissions: simulate a read-only folder
        real_access = os.access

        def access(path, mode, *args, **kwargs):
            if os.path.realpath(path) == str(ro.resolve()) and mode & os.W_OK:
                return False
            return real_access(path, mode, *args, **kwargs)

        monkeypatch.setattr(os, "access", access)
    fitted = []
    monkeypatch.setattr(RandomPhase, "_fit", lambda self, ex: fitted.append(1))
    before = snapshot(work)
    for args in (
        ["synth", "-o", "ro/o.png", *FAST],
        ["animate", "-o", "ro/a.gif", "-q"],
        ["compare", "-o", "ro/r.html", "-q"],
    ):
        code, err = run(capsys, *args)
        check_one_line(code, err, 2, "is not writable")
    assert fitted == []
    ro.chmod(0o755)
    assert snapshot(work) == before


# ---------------------------------------------------------------------------- internal faults
@pytest.mark.parametrize(
    "error", [RuntimeError("boom"), ValueError("boom"), TypeError("boom"), KeyError("boom")]
)
def test_an_internal_error_is_exit_1_not_the_users_fault(work, capsys, monkeypatch, error):
    def broken(self, shape, rng, callback):
        raise error

    monkeypatch.setattr(RandomPhase, "_sample", broken)
    before = snapshot(work)
    code, err = run(capsys, "synth", "-o", "o.png", *FAST)
    check_one_line(code, err, 1, f"{type(error).__name__}: ", prefix="texsyn: internal error: ")
    assert "boom" in err and "--debug" in err
    assert snapshot(work) == before

    code, err = run(capsys, "--debug", "synth", "-o", "o.png", *FAST)
    assert code == 1 and "Traceback" in err and "in broken" in err
    assert err.strip().splitlines()[-1].startswith("texsyn: internal error: ")
    monkeypatch.setenv("TEXSYN_DEBUG", "1")
    code, err = run(capsys, "synth", "-o", "o.png", *FAST)
    assert code == 1 and "Traceback" in err
    assert snapshot(work) == before


def test_running_out_of_memory_is_exit_1_with_a_clear_line(work, capsys, monkeypatch):
    def hungry(self, shape, rng, callback):
        raise MemoryError()

    monkeypatch.setattr(RandomPhase, "_sample", hungry)
    before = snapshot(work)
    code, err = run(capsys, "synth", "-o", "o.png", *FAST)
    check_one_line(code, err, 1, "out of memory")
    assert snapshot(work) == before


# ---------------------------------------------------------------------------- write failures
def no_space(*args, **kwargs):
    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


@pytest.mark.parametrize("method", ["quilting", "cwt"])
def test_disk_full_on_the_second_output_leaves_no_output(work, capsys, monkeypatch, method):
    """Quilting streams its rows to both files (``texsyn.io.streaming``), cwt writes them whole."""
    monkeypatch.setattr(writing, "_encode_array", no_space)
    monkeypatch.setattr(streaming.NpyRows, "_write", no_space)
    before = snapshot(work)
    code, err = run(
        capsys, "synth", "ex.png", "-o", "out.png", "--source-map", "where.npy", "-m", method, "-q"
    )
    check_one_line(code, err, 1, "cannot write 'where.npy': No space left on device")
    assert snapshot(work) == before  # neither out.png, nor its sidecar, nor a temporary


def test_disk_full_on_the_sidecar_keeps_the_previous_outputs(work, capsys, monkeypatch):
    monkeypatch.setattr(writing, "_encode_text", no_space)
    before = snapshot(work)
    code, err = run(capsys, "synth", "-o", "existing.png", "--overwrite", *FAST)
    check_one_line(code, err, 1, "cannot write 'existing.png.json': No space left on device")
    assert snapshot(work) == before


def test_permission_denied_while_writing(work, capsys, monkeypatch):
    def denied(*args, **kwargs):
        raise PermissionError(errno.EACCES, os.strerror(errno.EACCES))

    monkeypatch.setattr(writing, "_encode_image", denied)
    before = snapshot(work)
    code, err = run(capsys, "synth", "ex.png", "-o", "m.png", *FAST)
    check_one_line(code, err, 1, "cannot write 'm.png': Permission denied")
    assert snapshot(work) == before


def test_a_failed_rename_undoes_the_renames_already_done(work, capsys, monkeypatch):
    real_replace = os.replace

    def replace(src, dst, *args, **kwargs):
        if str(src).endswith(".part") and Path(dst).name == "existing.png.json":
            raise OSError(errno.EIO, os.strerror(errno.EIO))
        return real_replace(src, dst, *args, **kwargs)

    monkeypatch.setattr(writing.os, "replace", replace)
    (work / "existing.png.json").write_text('{"old": true}')
    before = snapshot(work)
    code, err = run(capsys, "synth", "-o", "existing.png", "--overwrite", *FAST)
    check_one_line(code, err, 1, "cannot write 'existing.png.json'")
    assert snapshot(work) == before  # the replaced image is put back, byte for byte


def test_an_interrupt_while_writing_removes_every_temporary(work, capsys, monkeypatch):
    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(writing, "_encode_text", interrupted)
    before = snapshot(work)
    code, err = run(
        capsys, "synth", "ex.png", "-o", "out.png", "--source-map", "where.npy", "-p", "patch_size=8", "-q"
    )
    assert code == 130 and err.strip() == "texsyn: interrupted"
    assert snapshot(work) == before


def test_mp4_writer_failure_leaves_nothing(work, capsys, monkeypatch):
    monkeypatch.setattr(writing._FfmpegWriter, "close", no_space)
    before = snapshot(work)
    code, err = run(
        capsys, "animate", "-o", "a.mp4", "--frames", "2", "--size", "16x16", "-q", "-p", "n_iterations=1"
    )
    check_one_line(code, err, 1, "cannot write 'a.mp4': No space left on device")
    assert snapshot(work) == before


@pytest.mark.parametrize(
    "script, message",
    [
        (
            'cat > /dev/null\necho "av_interleaved_write_frame(): No space left on device" >&2\nexit 1',
            "No space left on device",
        ),
        ('echo "Error opening output file: Permission denied" >&2\nexit 1', "Permission denied"),
        ("cat > /dev/null\nexit 0", "empty file"),  # ffmpeg says yes but wrote nothing
    ],
    ids=["disk full", "dies at once", "empty file"],
)
def test_ffmpeg_failures_are_reported(work, capsys, monkeypatch, tmp_path_factory, script, message):
    fake = tmp_path_factory.mktemp("bin") / "ffmpeg"
    fake.write_text("#!/bin/sh\n" + script + "\n")
    fake.chmod(0o755)
    monkeypatch.setattr(writing, "_ffmpeg_exe", lambda: str(fake))
    before = snapshot(work)
    code, err = run(
        capsys, "animate", "-o", "a.mp4", "--frames", "2", "--size", "16x16", "-q", "-p", "n_iterations=1"
    )
    check_one_line(code, err, 1, "cannot write 'a.mp4'")
    assert message in err
    assert snapshot(work) == before


# ---------------------------------------------------------------------------- signals
def start_animation(folder: Path, output: str) -> subprocess.Popen:
    # like an interactive process even when the test runs where SIGINT is ignored (background jobs)
    code = "import signal, sys; signal.signal(signal.SIGINT, signal.default_int_handler); from texsyn.cli import main; sys.exit(main())"
    args = ["animate", "builtin:brick", "-o", output, "--frames", "200", "--size", "64x64", "-q"]
    return subprocess.Popen(
        [sys.executable, "-c", code, *args], cwd=folder, stderr=subprocess.PIPE, text=True
    )


def wait_for_temporary(folder: Path, prefix: str, proc: subprocess.Popen, timeout: float = 60.0) -> None:
    end = time.monotonic() + timeout
    while time.monotonic() < end and proc.poll() is None:
        if any(p.name.startswith(prefix) for p in folder.iterdir()):
            time.sleep(0.2)  # frames are being written
            return
        time.sleep(0.05)
    pytest.fail("the animation did not start writing")


@pytest.mark.parametrize(
    "output, sig, status, line",
    [
        ("out.mp4", signal.SIGTERM, 143, "texsyn: terminated"),
        ("frames", signal.SIGINT, 130, "texsyn: interrupted"),
    ],
    ids=["mp4 SIGTERM", "frames SIGINT"],
)
def test_a_signal_during_animate_leaves_nothing_behind(tmp_path, output, sig, status, line):
    proc = start_animation(tmp_path, output)
    try:
        wait_for_temporary(tmp_path, f".{output}.", proc)
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == status, err
    assert err.strip() == line
    assert list(tmp_path.iterdir()) == []


# ---------------------------------------------------------------------------- fuzzing
NASTY = [
    "nan",
    "NaN",
    "-nan",
    "inf",
    "-inf",
    "Infinity",
    "1e400",
    "-1e400",
    "1e-400",
    "0",
    "-0",
    "-1",
    "1e308",
    "",
    " ",
    "abc",
    "0x10",
    "1_0",
    "9" * 40,
    "١٢",
    "2x",
    "x2",
    "3x3x3",
    "1,2",
    "none",
    "true",
    "nan,1",
]
OPTIONS = [
    "--scale",
    "--size",
    "--seed",
    "-p patch_size",
    "-p tolerance",
    "-p overlap",
    "-p periodic_component",
]
values = st.one_of(
    st.sampled_from(NASTY),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.integers(-(10**30), 10**30).map(str),
    st.tuples(st.integers(-3, 70), st.integers(-3, 70)).map(lambda t: f"{t[0]}x{t[1]}"),
    st.text(max_size=6),
)


@settings(max_examples=50, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(option=st.sampled_from(OPTIONS), value=values)
def test_fuzzed_option_values_exit_0_or_2_never_a_traceback(tmp_path, monkeypatch, option, value):
    monkeypatch.setenv("TEXSYN_MEMORY_LIMIT", "8M")  # large valid requests are refused up front, quickly
    exemplar = tmp_path / "small.png"
    if not exemplar.exists():
        Image.fromarray((texsyn.data.exemplar("brick", size=12) * 255).astype(np.uint8)).save(exemplar)
    if option.startswith("-p "):
        name = option.split()[1]
        method = "random_phase" if name == "periodic_component" else "quilting"
        extra = ["-m", method, "-p", f"{name}={value}"]
    else:
        extra = ["-m", "random_phase", option, value]
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        code = main(["synth", str(exemplar), "-o", str(tmp_path / "out.png"), "--overwrite", "-q", *extra])
    text = err.getvalue()
    assert code in (0, 2), text
    assert "Traceback" not in text and "internal error" not in text
    assert len(text.strip().splitlines()) <= 1, text
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_an_empty_file_name_is_a_missing_file_not_the_current_folder(tmp_path, capsys):
    from texsyn.cli import main

    code = main(["synth", "", "-o", str(tmp_path / "o.png")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "no such file" in err[0], err
    assert not any(tmp_path.iterdir())


def test_an_error_a_signal_caused_inside_compiled_code_reports_the_signal(monkeypatch, capsys):
    """A handler raising inside a numba function surfaces as ``SystemError: ... returned a
    result with an exception set``, with or without the signal's exception chained to it."""
    from texsyn.cli import app

    state = app.State(debug=False, argv=[])
    chained = SystemError("CPUDispatcher(f) returned a result with an exception set")
    chained.__context__ = KeyboardInterrupt()
    assert app.report_error(chained, state) == 130
    bare = SystemError("CPUDispatcher(f) returned a result with an exception set")
    monkeypatch.setattr(app, "_RECEIVED", [signal.SIGTERM])
    assert app.report_error(bare, state) == 143
    monkeypatch.setattr(app, "_RECEIVED", [])
    assert app.report_error(bare, state) == 1  # no signal: an internal error
    err = capsys.readouterr().err.splitlines()
    assert err[0] == "texsyn: interrupted" and err[1] == "texsyn: terminated"
    assert err[2].startswith("texsyn: internal error: SystemError")
