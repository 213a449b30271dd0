"""texsyn.io.OutputSet and the writers built on it: all or none, overwrite policy, permissions."""

import os
import stat

import numpy as np
import pytest

from texsyn.cli import main
from texsyn.errors import OutputExistsError, OutputFolderNotFoundError, OutputPathError
from texsyn.io import (
    OutputSet,
    read_image,
    sidecar_path,
    write_array,
    write_frames,
    write_image,
)
from texsyn.io.writing import JSON_FORMATS


def test_sidecar_names_append_json():
    assert sidecar_path("out.png").name == "out.png.json"
    assert sidecar_path("a/b/anim.mp4").as_posix() == "a/b/anim.mp4.json"
    assert sidecar_path("frames").name == "frames.json"


def test_an_error_inside_the_set_writes_nothing(tmp_path):
    outputs = OutputSet()
    a, b = outputs.claim(tmp_path / "a.png"), outputs.claim(tmp_path / "b.npy", formats={".npy": (8,)})
    with pytest.raises(RuntimeError, match="later failure"), outputs:
        outputs.write_image(a, np.zeros((4, 4)))
        outputs.write_array(b, np.arange(3))
        raise RuntimeError("later failure")
    assert list(tmp_path.iterdir()) == []


def test_a_committed_set_writes_everything_with_normal_permissions(tmp_path):
    outputs = OutputSet()
    image = outputs.claim(tmp_path / "a.png")
    text = outputs.claim(tmp_path / "a.png.json", formats={".json": (8,)})
    frames = outputs.claim(tmp_path / "frames", folder=True)
    with outputs:
        outputs.write_image(image, np.full((4, 5), 0.5))
        outputs.write_text(text, "{}")
        outputs.write_frames(frames, (np.zeros((4, 4)) for _ in range(3)))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.png", "a.png.json", "frames"]
    assert read_image(image).shape == (4, 5)
    assert sorted(p.name for p in frames.iterdir()) == [
        "frame_00000.png",
        "frame_00001.png",
        "frame_00002.png",
    ]
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE(image.stat().st_mode) == 0o666 & ~umask
    assert stat.S_IMODE(frames.stat().st_mode) == 0o777 & ~umask


def test_claims_are_checked_before_any_work(tmp_path):
    (tmp_path / "in.png").write_bytes(b"x")
    (tmp_path / "old.png").write_bytes(b"x")
    (tmp_path / "sub").mkdir()
    outputs = OutputSet(inputs=[("exemplar", tmp_path / "in.png")])
    with pytest.raises(OutputPathError, match="is the exemplar"):
        outputs.claim(tmp_path / "sub" / ".." / "in.png")
    with pytest.raises(OutputExistsError, match="overwrite=True"):
        outputs.claim(tmp_path / "old.png")
    with pytest.raises(OutputFolderNotFoundError, match="does not exist"):
        outputs.claim(tmp_path / "nowhere" / "x.png")
    outputs.claim(tmp_path / "x.png")
    with pytest.raises(OutputPathError, match="same file"):
        outputs.claim(tmp_path / "." / "x.png")
    # an input declared after the output is checked too
    with pytest.raises(OutputPathError, match="is the flow"):
        outputs.add_input(tmp_path / "x.png", "flow")


def test_an_output_that_appears_during_the_work_is_not_replaced(tmp_path):
    outputs = OutputSet()
    out = outputs.claim(tmp_path / "a.png")
    out.write_bytes(b"someone else's")
    with pytest.raises(OutputExistsError), outputs:
        outputs.write_image(out, np.zeros((2, 2)))
    assert out.read_bytes() == b"someone else's"
    assert [p.name for p in tmp_path.iterdir()] == ["a.png"]


def test_single_file_writers_overwrite_by_default_and_refuse_on_request(tmp_path):
    path = tmp_path / "a.png"
    write_image(path, np.zeros((2, 2)))
    write_image(path, np.ones((3, 3)))
    assert read_image(path).shape == (3, 3)
    with pytest.raises(OutputExistsError):
        write_image(path, np.zeros((2, 2)), overwrite=False)
    write_array(tmp_path / "a.npy", np.zeros(2))
    with pytest.raises(OutputExistsError):
        write_array(tmp_path / "a.npy", np.ones(2), overwrite=False)
    assert np.load(tmp_path / "a.npy").tolist() == [0, 0]
    assert read_image(path).shape == (3, 3)


def test_frame_folders_empty_or_replaced_only_with_overwrite(tmp_path, capsys):
    frames = tmp_path / "frames"
    frames.mkdir()  # an existing empty folder receives the frames without --overwrite
    args = [
        "animate",
        "builtin:brick",
        "-o",
        str(frames),
        "--frames",
        "2",
        "--size",
        "16x16",
        "-q",
        "-p",
        "n_iterations=1",
        "--seed",
        "1",
    ]
    assert main(args) == 0, capsys.readouterr().err
    assert sorted(p.name for p in frames.iterdir()) == ["frame_00000.png", "frame_00001.png"]
    assert main(args) == 2 and "already exists" in capsys.readouterr().err
    args[args.index("2")] = "3"
    assert main(args + ["--overwrite"]) == 0
    assert len(list(frames.iterdir())) == 3
    assert sorted(p.name for p in tmp_path.iterdir()) == ["frames", "frames.json"]


def test_write_frames_library_folder(tmp_path):
    write_frames(tmp_path / "f", [np.zeros((4, 4)), np.ones((4, 4))])
    assert len(list((tmp_path / "f").iterdir())) == 2
    (tmp_path / "f" / "notes.txt").write_text("mine")
    with pytest.raises(OutputPathError, match="other than frame"):
        write_frames(tmp_path / "f", [np.zeros((4, 4))])
    assert (tmp_path / "f" / "notes.txt").read_text() == "mine"


def test_commit_flushes_its_outputs_and_the_folder_not_the_folders_other_files(tmp_path, monkeypatch):
    """A command writing into a folder of 40 photos flushes its 2 files and the folder's
    entries, not the photos (issue 20: 64 fsyncs cost 0.25 s of a 0.5 s command)."""
    for i in range(40):
        (tmp_path / f"photo{i}.jpg").write_bytes(b"x")
    calls = []
    real = os.fsync
    monkeypatch.setattr(os, "fsync", lambda fd: calls.append(fd) or real(fd))
    outputs = OutputSet()
    image, side = (
        outputs.claim(tmp_path / "o.png"),
        outputs.claim(tmp_path / "o.png.json", formats=JSON_FORMATS),
    )
    with outputs:
        outputs.write_image(image, np.zeros((4, 4)))
        outputs.write_text(side, "{}")
    assert len(calls) == 3
