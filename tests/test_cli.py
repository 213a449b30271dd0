"""The command line through its entry point: exit codes, files written, nothing on error."""

import json
import shlex

import numpy as np
import pytest
from PIL import Image

import texsyn
from conftest import FAST_PARAMS
from texsyn.cli import main
from texsyn.io import read_image


@pytest.fixture
def exemplar_file(tmp_path):
    path = tmp_path / "ex.png"
    Image.fromarray((texsyn.data.exemplar("gravel", size=48) * 255).astype(np.uint8)).save(path)
    return path


def run(capsys, *args):
    code = main([str(a) for a in args])
    out = capsys.readouterr()
    return code, out.out, out.err


def test_synth_writes_the_requested_size(tmp_path, exemplar_file, capsys):
    out = tmp_path / "out.png"
    code, _, err = run(
        capsys,
        "synth",
        exemplar_file,
        "-o",
        out,
        "--size",
        "70x50",
        "--seed",
        "1",
        "-p",
        "patch_size=16",
        "-q",
    )
    assert code == 0, err
    assert read_image(out).shape == (50, 70)
    assert err == ""


def test_synth_defaults_to_twice_the_exemplar_and_same_seed_same_file(tmp_path, exemplar_file, capsys):
    a, b = tmp_path / "a.png", tmp_path / "b.png"
    for path in (a, b):
        assert run(capsys, "synth", exemplar_file, "-o", path, "--seed", "5", "-m", "random_phase")[0] == 0
    assert read_image(a).shape == (96, 96)
    assert a.read_bytes() == b.read_bytes()


def test_synth_scale_bit_depth_and_source_map(tmp_path, exemplar_file, capsys):
    out, src, pic = tmp_path / "o.tif", tmp_path / "src.npy", tmp_path / "src.png"
    code, _, err = run(
        capsys,
        "synth",
        exemplar_file,
        "-o",
        out,
        "--scale",
        "0.75",
        "--bit-depth",
        "16",
        "-p",
        "patch_size=12",
        "--source-map",
        src,
        "-q",
    )
    assert code == 0, err
    img = read_image(out)
    assert img.shape == (36, 36)
    ex = read_image(exemplar_file)
    source = np.load(src)
    np.testing.assert_allclose(img, ex[source[..., 0], source[..., 1]], atol=1e-4)
    assert (
        run(
            capsys,
            "synth",
            exemplar_file,
            "-o",
            tmp_path / "o2.png",
            "--source-map",
            pic,
            "-q",
            "-p",
            "patch_size=12",
        )[0]
        == 0
    )
    assert read_image(pic).shape == (96, 96, 3)


def test_synth_without_exemplar_uses_the_builtin(tmp_path, capsys):
    out = tmp_path / "brick.png"
    code, _, err = run(capsys, "synth", "-o", out, "--size", "64x64")
    assert code == 0
    assert read_image(out).shape == (64, 64)
    assert "built-in brick" in err
    assert run(capsys, "synth", "builtin:grass", "-o", out, "--size", "40x40", "-q", "--overwrite")[0] == 0
    assert read_image(out).shape == (40, 40)


def test_methods_lists_every_method_with_parameters(capsys):
    code, out, _ = run(capsys, "methods")
    assert code == 0
    for name, cls in texsyn.METHODS.items():
        assert f"{name}: {cls.summary}" in out
        for spec in cls.param_specs().values():
            assert f"{spec.name} = " in out
    assert "patch_size = 32  (int, allowed [2, 1024])" in out


def test_version(capsys):
    code, out, _ = run(capsys, "--version")
    assert code == 0 and texsyn.__version__ in out


def truncated_png(tmp_path):
    good = tmp_path / "good.png"
    noise = (np.random.default_rng(0).random((64, 64)) * 255).astype(np.uint8)
    Image.fromarray(noise).save(good)
    path = tmp_path / "trunc.png"
    data = good.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    return path


def not_an_image(tmp_path):
    path = tmp_path / "notes.png"
    path.write_text("this is text")
    return path


def tiny_image(tmp_path):
    path = tmp_path / "tiny.png"
    Image.fromarray(np.zeros((1, 1), np.uint8)).save(path)
    return path


def small_image(tmp_path):
    path = tmp_path / "small.png"
    Image.fromarray(np.zeros((12, 12), np.uint8)).save(path)
    return path


BAD_INPUTS = [
    ("missing file", lambda t: [t / "missing.png"], "no such file"),
    ("not an image", lambda t: [not_an_image(t)], "cannot read"),
    ("truncated png", lambda t: [truncated_png(t)], "cannot read"),
    ("1-pixel image", lambda t: [tiny_image(t)], "at least 2x2"),
    ("exemplar smaller than the patch", lambda t: [small_image(t)], "too small for method 'quilting'"),
    (
        "window larger than exemplar",
        lambda t: [small_image(t), "-m", "efros_leung", "-p", "window_size=15"],
        "too small",
    ),
    ("unknown method", lambda t: ["-m", "nope"], "unknown method 'nope'"),
    ("unknown parameter", lambda t: ["-p", "bogus=1"], "unknown parameter 'bogus'"),
    ("out of range", lambda t: ["-p", "patch_size=-3"], "must be in [2, 1024], got -3"),
    ("not a number", lambda t: ["-p", "tolerance=abc"], "parameter 'tolerance'"),
    ("malformed parameter", lambda t: ["-p", "patch_size"], "NAME=VALUE"),
    # quilting streams its rows (docs/performance.md): a method that holds its canvas is refused
    ("too large", lambda t: ["-m", "heeger_bergen", "--size", "90000x90000"], "memory"),
    ("side too large", lambda t: ["--size", "200000x200000"], "at most 100000"),
    ("bad size", lambda t: ["--size", "12by4"], "WIDTHxHEIGHT"),
    ("size and scale", lambda t: ["--size", "10x10", "--scale", "2"], "either --size or --scale"),
    ("no source map", lambda t: ["-m", "random_phase", "--source-map", t / "s.npy"], "no source map"),
]


@pytest.mark.parametrize("label, make_args, message", BAD_INPUTS, ids=[b[0] for b in BAD_INPUTS])
def test_bad_input_one_line_exit_2_no_output(tmp_path, capsys, label, make_args, message):
    out = tmp_path / "out.png"
    args = make_args(tmp_path)
    code, stdout, err = run(capsys, "synth", *args, "-o", out)
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("texsyn: error: ")
    assert message in lines[0]
    assert "Traceback" not in err
    assert not out.exists()
    assert not (tmp_path / "out.png.json").exists()
    leftovers = [p.name for p in tmp_path.iterdir() if p.name.startswith(".")]
    assert leftovers == []


def test_output_in_a_missing_folder(tmp_path, capsys):
    code, _, err = run(capsys, "synth", "-o", tmp_path / "nowhere" / "o.png")
    assert code == 2 and "does not exist" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "nowhere").exists()


def test_existing_output_is_not_overwritten_on_error(tmp_path, capsys):
    out = tmp_path / "keep.png"
    out.write_bytes(b"previous result")
    code, _, _ = run(capsys, "synth", "-o", out, "-p", "patch_size=0")
    assert code == 2
    assert out.read_bytes() == b"previous result"


def test_unsupported_output_type_and_usage_errors(tmp_path, capsys):
    code, _, err = run(capsys, "synth", "-o", tmp_path / "o.xyz")
    assert code == 2 and "unsupported file type" in err
    code, _, err = run(capsys, "synth")
    assert code == 2 and len(err.strip().splitlines()) == 1 and "--output" in err
    code, _, err = run(capsys, "frobnicate")
    assert code == 2 and len(err.strip().splitlines()) == 1


def test_no_arguments_prints_the_help(capsys):
    code, out, err = run(capsys)
    assert code == 0 and err == ""
    assert "Usage: texsyn" in out and "synth" in out and "--debug" in out


def test_synth_writes_a_sidecar_with_method_parameters_seed_and_command(tmp_path, exemplar_file, capsys):
    out, src = tmp_path / "out.png", tmp_path / "where.npy"
    args = [
        "synth",
        exemplar_file,
        "-o",
        out,
        "--size",
        "40x32",
        "--seed",
        "11",
        "-p",
        "patch_size=12",
        "--source-map",
        src,
        "-q",
    ]
    code, _, err = run(capsys, *args)
    assert code == 0, err
    side = json.loads((tmp_path / "out.png.json").read_text())
    assert side["texsyn_version"] == texsyn.__version__
    assert side["command"] == "synth" and side["method"] == "quilting"
    assert side["params"] == {
        k: list(v) if isinstance(v, tuple) else v
        for k, v in texsyn.make_method("quilting", patch_size=12).get_params().items()
    }
    assert side["seed"] == 11
    assert side["inputs"] == {"exemplar": str(exemplar_file)}
    assert side["outputs"] == {"image": str(out), "source_map": str(src), "sidecar": str(out) + ".json"}
    assert side["options"]["size"] == [40, 32]
    assert shlex.split(side["command_line"]) == ["texsyn"] + [str(a) for a in args]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ex.png", "out.png", "out.png.json", "where.npy"]


def test_synth_writes_the_methods_diagnostics_into_the_sidecar(tmp_path, exemplar_file, capsys):
    out = tmp_path / "ps.png"
    ps = ("-p", "n_scales=2", "-p", "n_iterations=3", "-p", "record_distance=true")
    code, _, err = run(
        capsys, "synth", exemplar_file, "-o", out, "-m", "portilla_simoncelli", *ps, "--size", "32x32", "-q"
    )
    assert code == 0, err
    diagnostics = json.loads((tmp_path / "ps.png.json").read_text())["diagnostics"]
    assert diagnostics is not None  # texsyn 0.2 dropped what record_distance measured
    distance = diagnostics["statistics_distance"]
    assert len(distance) == 3 and all(isinstance(d, float) for d in distance)
    by_family = diagnostics["statistics_distance_by_family"]
    assert by_family and all(len(v) == 3 and all(isinstance(d, float) for d in v) for v in by_family.values())
    out = tmp_path / "sparse.png"
    small = [f"{k}={v}" for k, v in FAST_PARAMS["sparse"].items()]
    args = [a for p in small for a in ("-p", p)]
    code, _, err = run(
        capsys, "synth", exemplar_file, "-o", out, "-m", "sparse", *args, "--size", "24x24", "-q"
    )
    assert code == 0, err
    diagnostics = json.loads((tmp_path / "sparse.png.json").read_text())["diagnostics"]
    energy = diagnostics["energy"]
    assert energy and all(isinstance(e, float) and e > 0 for e in energy)
    assert len(diagnostics["energy_scale"]) == len(energy) == sum(diagnostics["iterations"])
    assert all(isinstance(c, bool) for c in diagnostics["converged"])
    out = tmp_path / "rp.png"
    assert run(capsys, "synth", exemplar_file, "-o", out, "-m", "random_phase", "-q")[0] == 0
    assert json.loads((tmp_path / "rp.png.json").read_text())["diagnostics"] is None


def test_a_drawn_seed_is_printed_recorded_and_reproduces_the_texture(tmp_path, exemplar_file, capsys):
    first, second = tmp_path / "a.png", tmp_path / "b.png"
    code, _, err = run(capsys, "synth", exemplar_file, "-o", first, "-m", "random_phase")
    assert code == 0, err
    seeds = [line for line in err.splitlines() if line.startswith("seed: ")]
    assert len(seeds) == 1
    seed = int(seeds[0].split()[1])
    assert 0 <= seed < 2**32
    assert json.loads((tmp_path / "a.png.json").read_text())["seed"] == seed
    code, _, err = run(capsys, "synth", exemplar_file, "-o", second, "-m", "random_phase", "--seed", seed)
    assert code == 0 and "seed:" not in err  # printed only when drawn
    assert first.read_bytes() == second.read_bytes()
    code, _, err = run(capsys, "synth", exemplar_file, "-o", tmp_path / "c.png", "-m", "random_phase", "-q")
    assert code == 0 and err == ""  # --quiet: no seed line either


def test_overwrite_replaces_the_output_and_its_sidecar(tmp_path, exemplar_file, capsys):
    out = tmp_path / "out.png"
    common = ("synth", exemplar_file, "-o", out, "-m", "random_phase", "-q")
    assert run(capsys, *common, "--size", "20x20", "--seed", "1")[0] == 0
    assert run(capsys, *common, "--size", "30x20", "--seed", "2", "--overwrite")[0] == 0
    assert read_image(out).shape == (20, 30)
    assert json.loads((tmp_path / "out.png.json").read_text())["seed"] == 2
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ex.png", "out.png", "out.png.json"]


def test_modify_and_animate_write_sidecars(tmp_path, exemplar_file, capsys):
    out = tmp_path / "m.png"
    code, _, err = run(
        capsys, "modify", exemplar_file, "-e", exemplar_file, "-o", out, "-q", "-p", "lle_points=64"
    )
    assert code == 0, err
    side = json.loads((tmp_path / "m.png.json").read_text())
    assert side["method"] == "patch_wavelet" and side["seed"] is None
    assert side["inputs"] == {"input": str(exemplar_file), "exemplar": str(exemplar_file)}
    assert side["options"]["ratio"] == 0.5
    frames = tmp_path / "frames"
    code, _, err = run(
        capsys,
        "animate",
        "builtin:brick",
        "-o",
        frames,
        "--frames",
        "2",
        "--size",
        "16x16",
        "-q",
        "-p",
        "n_iterations=1",
    )
    assert code == 0, err
    side = json.loads((tmp_path / "frames.json").read_text())
    assert side["method"] == "grouplets" and isinstance(side["seed"], int)
    assert side["outputs"]["frames"] == str(frames) and side["options"]["frames"] == 2
