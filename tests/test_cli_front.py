"""The command line as a front door (issue 17): deprecated parameter names arrive through the
registry and show as one warning line; only the user's mistakes are exit 2; the default
output shape is the library's."""

from __future__ import annotations

import errno
import os

import pytest

import texsyn
from texsyn.cli import main
from texsyn.io import read_image
from texsyn.methods import METHODS, RandomPhase
from texsyn.ops.canvas import default_output_shape


def run(capsys, *args) -> tuple[int, str]:
    code = main([str(a) for a in args])
    return code, capsys.readouterr().err


class RenamedPhase(RandomPhase):
    """random_phase, whose ``periodic_component`` had another name in an older release."""

    name = "renamed_phase"
    deprecated_params = {"periodic": "periodic_component"}


@pytest.fixture
def renamed(monkeypatch):
    monkeypatch.setitem(METHODS, RenamedPhase.name, RenamedPhase)
    return RenamedPhase.name


def test_an_old_parameter_name_works_with_one_warning_line(tmp_path, capsys, renamed):
    old, new = tmp_path / "old.png", tmp_path / "new.png"
    code, err = run(capsys, "synth", "-o", old, "-m", renamed, "--size", "16x16", "--seed", "3", "-q",
                    "-p", "periodic=false")  # fmt: skip
    assert code == 0, err
    assert err.splitlines() == [
        "texsyn: warning: parameter 'periodic' of method 'renamed_phase' is deprecated; use 'periodic_component'"
    ]
    assert run(capsys, "synth", "-o", new, "-m", renamed, "--size", "16x16", "--seed", "3", "-q",
               "-p", "periodic_component=false")[1] == ""  # fmt: skip
    assert old.read_bytes() == new.read_bytes()
    side = (tmp_path / "old.png.json").read_text()
    assert '"periodic_component": false' in side and '"periodic"' not in side


def test_an_old_and_a_new_name_together_are_bad_input(tmp_path, capsys, renamed):
    code, err = run(capsys, "synth", "-o", tmp_path / "o.png", "-m", renamed, "--size", "16x16", "-q",
                    "-p", "periodic=false", "-p", "periodic_component=true")  # fmt: skip
    assert code == 2 and "give only 'periodic_component'" in err
    assert "Traceback" not in err and not (tmp_path / "o.png").exists()


def test_an_old_name_in_compare_parameters(tmp_path, capsys, renamed):
    code, err = run(capsys, "compare", "-o", tmp_path / "r.html", "-m", renamed, "--size", "16x16", "-q",
                    "-p", f"{renamed}.periodic=false")  # fmt: skip
    assert code == 0, err
    assert "texsyn: warning: parameter 'periodic'" in err and len(err.splitlines()) == 1


@pytest.mark.parametrize("name", sorted(METHODS))
def test_every_deprecated_name_is_accepted_by_the_parser(name, recwarn):
    from texsyn.cli.options import parse_params

    cls = METHODS[name]
    specs = cls.param_specs()
    for old, new in cls.deprecated_params.items():
        value = specs[new].default
        text = str(value).lower() if isinstance(value, bool) else str(value)
        assert parse_params(name, (f"{old}={text}",)) == {new: value}
        assert any(issubclass(w.category, DeprecationWarning) and old in str(w.message) for w in recwarn)


@pytest.mark.parametrize(
    "error",
    [OSError(errno.EIO, "Input/output error"), PermissionError(errno.EACCES, "Permission denied", "/etc/x")],
    ids=["OSError", "PermissionError"],
)
def test_a_system_error_during_work_is_exit_1_not_2(tmp_path, capsys, monkeypatch, error):
    def broken(self, shape, rng, callback):
        raise error

    monkeypatch.setattr(RandomPhase, "_sample", broken)
    code, err = run(capsys, "synth", "-o", tmp_path / "o.png", "-m", "random_phase", "--size", "16x16", "-q")
    assert code == 1, err
    assert err.startswith("texsyn: error: ") and len(err.splitlines()) == 1
    assert os.listdir(tmp_path) == []


def test_the_default_output_shape_is_the_librarys(tmp_path, capsys):
    out = tmp_path / "o.png"
    assert run(capsys, "synth", "builtin:grass", "-o", out, "-m", "random_phase", "--seed", "1", "-q")[0] == 0
    exemplar = texsyn.data.exemplar("grass")
    assert read_image(out).shape[:2] == default_output_shape(exemplar.shape)


def test_progress_json_writes_one_record_per_line_and_the_same_bytes(tmp_path, capfd):
    """``texsyn --progress json``: what ``texsyn serve`` reads (docs/cli.md)."""
    import json

    from texsyn.cli import main

    args = ["synth", "-m", "quilting", "--size", "64x64", "--seed", "3", "-p", "patch_size=16"]
    assert main(["--progress", "json", *args, "-o", str(tmp_path / "a.png")]) == 0
    lines = [line for line in capfd.readouterr().err.splitlines() if line.startswith("{")]
    records = [json.loads(line)["progress"] for line in lines]
    assert records and records[-1]["done"] == records[-1]["total"] and records[-1]["stage"] == "blocks"
    assert {"label", "stage", "done", "total", "elapsed"} <= set(records[0])
    assert [r["done"] for r in records] == sorted(r["done"] for r in records)
    assert main([*args, "-q", "-o", str(tmp_path / "b.png")]) == 0
    assert (tmp_path / "a.png").read_bytes() == (tmp_path / "b.png").read_bytes()
