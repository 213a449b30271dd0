"""``texsyn animate``: the options a motion designer sets, the video formats, the progress bar.

Every run is tiny (16x16 frames, 3 frames, one level and one projection) so that the file
runs in seconds; the animation itself is tested in ``test_grouplets.py``.
"""

import json

import imageio.v2 as iio2
import numpy as np
import pytest
from rich.progress import TimeElapsedColumn, TimeRemainingColumn

import texsyn
from texsyn.cli import main
from texsyn.cli.progress import ProgressBar
from texsyn.io import write_frames, writing
from texsyn.io.video import VIDEO_CODECS, count_video_frames
from texsyn.ops.progress import Progress

#: the smallest animation that still runs every step (the frame size apart)
FAST = (
    "--frames", "3", "--seed", "1", "-q",
    "-p", "n_iterations=1", "-p", "n_projections=1", "-p", "levels=1", "-p", "grouplet_levels=1",
)  # fmt: skip
TINY = (*FAST, "--size", "16x16")


def run(capsys, *args):
    code = main(["animate", "builtin:brick", *(str(a) for a in args)])
    return code, capsys.readouterr().err


def check_refused(code, err, tmp_path, message):
    """Exit 2, one ``texsyn: error:`` line naming ``message``, nothing written (no temporary)."""
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1, err
    assert lines[0].startswith("texsyn: error: ") and message in lines[0]
    assert list(tmp_path.iterdir()) == []


# ---------------------------------------------------------------------------- options
def test_each_option_reaches_the_method_and_the_sidecar(tmp_path, capsys):
    out = tmp_path / "frames"
    options = {"speed": 2.5, "turbulence": 0.5, "viscosity": 0.1, "initial_flow": "vortices"}
    flags = [a for name, value in options.items() for a in ("--" + name.replace("_", "-"), value)]
    code, err = run(capsys, "-o", out, *TINY, "--loop", "1", *flags)
    assert code == 0, err
    side = json.loads((tmp_path / "frames.json").read_text())
    for name, value in options.items():
        assert side["params"][name] == value, name
        assert side["options"][name] == value, name
    assert side["options"]["loop"] == 1 and side["options"]["frames"] == 3
    assert len(list(out.iterdir())) == 3


def test_options_not_given_record_the_method_defaults(tmp_path, capsys):
    code, err = run(capsys, "-o", tmp_path / "frames", *TINY)
    assert code == 0, err
    side = json.loads((tmp_path / "frames.json").read_text())
    defaults = texsyn.make_method("grouplets").get_params()
    for name in ("speed", "turbulence", "viscosity", "initial_flow"):
        assert side["options"][name] == side["params"][name] == defaults[name], name
    assert side["options"]["loop"] == 0


def test_help_shows_the_formats_the_options_and_the_loop(capsys):
    assert main(["animate", "--help"]) == 0
    text = " ".join(capsys.readouterr().out.split())
    for word in (".mp4", ".webm", ".gif", "--speed", "--turbulence", "--viscosity", "--initial-flow"):
        assert word in text
    assert "learned|turbulence|vortices|noise" in text
    assert "steers the flow back to its start over the last N frames" in text
    spec = texsyn.get_method("grouplets").param_specs()["speed"]
    assert f"[default: {spec.text(spec.default)}]" in text  # read from the signature, as -p writes it


BAD_OPTIONS = [
    (["--speed", "200"], "'speed'"),
    (["--speed", "nan"], "--speed"),
    (["--turbulence", "11"], "'turbulence'"),
    (["--turbulence", "-1"], "'turbulence'"),
    (["--viscosity", "-1"], "'viscosity'"),
    (["--initial-flow", "spiral"], "spiral"),
    (["--loop", "3"], "--loop must be smaller than --frames"),
    (["--loop", "1", "-p", "advection=paper"], "advection"),  # the method's own check, after fitting
]


@pytest.mark.parametrize("args, message", BAD_OPTIONS, ids=[" ".join(a) for a, _ in BAD_OPTIONS])
@pytest.mark.parametrize("name", ["a.webm", "frames"])
def test_bad_values_exit_2_with_one_line_and_no_file(tmp_path, capsys, args, message, name):
    code, err = run(capsys, "-o", tmp_path / name, *TINY, *args)
    check_refused(code, err, tmp_path, message)


@pytest.mark.parametrize(
    "option, value, param",
    [
        ("--speed", "2", "speed=1"),
        ("--initial-flow", "noise", "initial_flow=noise"),
        ("--viscosity", "0.1", "viscosity=0.2"),
    ],
)
def test_an_option_and_p_for_one_parameter_is_a_usage_error(tmp_path, capsys, option, value, param):
    code, err = run(capsys, "-o", tmp_path / "a.gif", *TINY, option, value, "-p", param)
    name = param.split("=")[0]
    check_refused(code, err, tmp_path, f"give {option} or -p {name}=..., not both")


def test_an_unknown_video_format_lists_webm(tmp_path, capsys):
    code, err = run(capsys, "-o", tmp_path / "a.avi", *TINY)
    check_refused(code, err, tmp_path, "use .mp4, .webm, .gif or a folder name")


# ---------------------------------------------------------------------------- webm
def test_webm_is_written_as_vp9_and_read_back(tmp_path, capsys):
    out = tmp_path / "a.webm"
    code, err = run(capsys, "-o", out, *FAST, "--size", "17x15")
    assert code == 0, err
    assert count_video_frames(out) == 3  # the check the writer makes
    with iio2.get_reader(out) as reader:
        assert reader.get_meta_data()["codec"] == "vp9"
        frames = [frame for frame in reader]  # list() would ask its length: infinite
    assert len(frames) == 3 and frames[0].shape == (15, 17, 3)  # VP9 keeps odd sides
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.webm", "a.webm.json"]
    assert json.loads((tmp_path / "a.webm.json").read_text())["outputs"]["video"] == str(out)


def test_every_ffmpeg_video_format_can_be_claimed():
    assert set(VIDEO_CODECS) <= set(writing.VIDEO_FORMATS)
    assert set(writing.VIDEO_FORMATS) - set(VIDEO_CODECS) == {".gif"}  # imageio writes GIFs


def test_write_frames_webm_from_python(tmp_path):
    rng = np.random.default_rng(0)
    path = write_frames(tmp_path / "noise.webm", (rng.random((8, 10)) for _ in range(4)), fps=12)
    assert count_video_frames(path) == 4


def test_a_failing_ffmpeg_leaves_no_webm(tmp_path, monkeypatch, tmp_path_factory):
    fake = tmp_path_factory.mktemp("bin") / "ffmpeg"
    fake.write_text(
        '#!/bin/sh\ncat > /dev/null\necho "av_interleaved_write_frame(): No space left on device" >&2\nexit 1\n'
    )
    fake.chmod(0o755)
    monkeypatch.setattr(writing, "_ffmpeg_exe", lambda: str(fake))
    with pytest.raises(OSError, match="cannot write .*a.webm.*No space left on device"):
        write_frames(tmp_path / "a.webm", [np.zeros((8, 8))] * 2)
    assert list(tmp_path.iterdir()) == []


# ---------------------------------------------------------------------------- progress bar
class FakeClock:
    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def test_the_progress_bar_shows_an_eta_beside_the_elapsed_time(capsys):
    clock = FakeClock()
    bar = ProgressBar("animate", enabled=True, delay=1.0, clock=clock)
    try:
        clock.now = 0.5
        bar(Progress("frames", 0, 10))
        assert bar._bar is None  # quick work draws nothing
        for now, done in [(2.0, 1), (3.0, 2), (4.0, 3)]:
            clock.now = now
            bar(Progress("frames", done, 10))
        columns = [type(c) for c in bar._bar.columns]
        elapsed = columns.index(TimeElapsedColumn)
        assert TimeRemainingColumn in columns[elapsed + 1 : elapsed + 3]  # "ETA" text between them
        (task,) = bar._bar.tasks
        assert task.elapsed == 4.0  # from the bar's creation, not from its first drawing
        assert task.time_remaining == 7  # one frame a second, seven to go
        clock.now = 5.0
        bar(Progress("iteration", 1, 20))  # a new stage counts other units: a new estimate
        (task,) = bar._bar.tasks
        assert task.time_remaining is None and task.elapsed == 5.0
        assert task.description == "animate (iteration)" and task.total == 20
    finally:
        bar.close()
    capsys.readouterr()


def test_a_quiet_progress_bar_draws_nothing(capsys):
    bar = ProgressBar("animate", enabled=False, delay=0.0)
    bar(Progress("frames", 1, 2))
    bar.close()
    assert bar._bar is None and capsys.readouterr().err == ""
