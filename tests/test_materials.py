"""Materials (issue 23, ``docs/materials.md``): bit depths and float formats end to end, ICC
profiles, linear light, alpha carried like colour, ``texsyn replay`` and material stacks in
register.

The material is built from one real texture (the built-in brick): a smooth 16-bit albedo,
its height (the albedo's luma, in metres, so outside [0, 1]), the normals of that height and
a roughness of ``1 - luma``. Because the images are made from one another, a synthesis keeps
them in register exactly when those relations still hold in its outputs; each check is
compared with the same relation on misregistered outputs (shifted by a few pixels), so that
it would fail if the images were synthesised apart.
"""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter

import texsyn
from texsyn.cli import main
from texsyn.errors import ImageReadError, InputError
from texsyn.io import read_image, read_image_file, write_image
from texsyn.ops.color import linear_to_srgb, luma, srgb_to_linear
from texsyn.ops.materials import LayerEncoding, replay, unit_normals

HEIGHT_SCALE, HEIGHT_OFFSET = 5.0, -2.0  # metres: a height map outside [0, 1]


def run(capsys, *args):
    code = main([str(a) for a in args])
    out = capsys.readouterr()
    return code, out.err


def one_line_error(code, err, words):
    assert code == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("texsyn: error: ") and words in lines[0], err


def albedo_of(size: int = 64) -> np.ndarray:
    grey = gaussian_filter(texsyn.data.exemplar("brick", size=size).astype(np.float64), 0.7)
    return np.clip(np.dstack([grey, grey**1.5, 0.25 + 0.5 * np.roll(grey, 5, axis=1)]), 0, 1)


def normals_of(height: np.ndarray) -> np.ndarray:
    gy, gx = np.gradient(height)
    return unit_normals(np.dstack([-8 * gx, -8 * gy, np.ones_like(gx)]), encoded=False)


@pytest.fixture(scope="module")
def material(tmp_path_factory):
    folder = tmp_path_factory.mktemp("material")
    albedo = albedo_of()
    write_image(folder / "albedo.png", albedo, bit_depth=16)
    albedo = read_image(folder / "albedo.png").astype(np.float64)  # as stored, 16-bit
    height = luma(albedo)
    np.save(folder / "height.npy", (HEIGHT_OFFSET + HEIGHT_SCALE * height).astype(np.float32))
    write_image(folder / "brick_normal.png", (normals_of(height) + 1) / 2, bit_depth=16)
    write_image(folder / "rough.png", 1 - height, bit_depth=16)
    return folder


def relation_errors(albedo, height_m, rough):
    """Mean |height - luma(albedo)| and |rough - (1 - luma)|, height back in [0, 1] units."""
    y = luma(albedo)
    height = (height_m - HEIGHT_OFFSET) / HEIGHT_SCALE
    return float(np.abs(height - y).mean()), float(np.abs(rough - (1 - y)).mean())


@pytest.mark.parametrize(
    "method, params, tolerance", [("quilting", "patch_size=16", 2e-4), ("mslg", "patch_size=8", 0.01)]
)
def test_a_material_stack_stays_in_register(tmp_path, material, capsys, method, params, tolerance):
    out = tmp_path / "out"
    code, err = run(
        capsys, "synth", material / "albedo.png", "--with", material / "brick_normal.png",
        "--with", material / "height.npy", "--with", material / "rough.png",
        "-o", out, "-m", method, "-p", params, "--size", "96x80", "--seed", "3", "-q",
    )  # fmt: skip
    assert code == 0, err
    albedo, normal = read_image_file(out / "albedo.png"), read_image_file(out / "brick_normal.png")
    height, rough = read_image_file(out / "height.npy"), read_image_file(out / "rough.png")
    assert (albedo.bit_depth, normal.bit_depth, height.bit_depth, rough.bit_depth) == (16, 16, 32, 16)
    assert albedo.pixels.shape == (80, 96, 3) and height.pixels.shape == (80, 96)
    assert len(np.unique(albedo.pixels[..., 0])) > 256  # 16-bit in, 16-bit out
    # quilting copies (quantisation only); mslg draws every channel from one joint Gaussian
    # and matches each channel's histogram, measured at 0.002 mean (tolerance 0.01)
    in_register = relation_errors(albedo.pixels, height.pixels, rough.pixels)
    shifted = relation_errors(np.roll(albedo.pixels, 3, axis=1), height.pixels, rough.pixels)
    assert max(in_register) < tolerance, in_register
    assert min(shifted) > 5 * max(in_register), (shifted, in_register)  # it sees a misregistration
    vectors = 2.0 * normal.pixels.astype(np.float64) - 1.0
    np.testing.assert_allclose(np.linalg.norm(vectors, axis=2), 1.0, atol=1e-4)
    exemplar_height = np.load(material / "height.npy")
    assert exemplar_height.min() - 1e-6 <= height.pixels.min() < 0 < 1 < height.pixels.max()  # metres kept
    sidecar = json.loads((out / "albedo.png.json").read_text())
    assert sidecar["options"]["stack"] == ("replay" if method == "quilting" else "joint")
    channels = {c["input"].rsplit("/", 1)[-1]: c for c in sidecar["options"]["channels"]}
    assert channels["brick_normal.png"]["normal"] is True
    assert channels["height.npy"]["bit_depth"] == "32f"
    assert channels["height.npy"]["value_range"][0] == pytest.approx(float(exemplar_height.min()))


def test_replay_carries_channels_as_the_stack_does(tmp_path, material, capsys):
    out, again, source = tmp_path / "out", tmp_path / "again", tmp_path / "map.npy"
    args = ["-p", "patch_size=16", "--size", "64x48", "--seed", "1", "-q"]
    code, err = run(
        capsys,
        "synth",
        material / "albedo.png",
        "--with",
        material / "height.npy",
        "-o",
        out,
        "--source-map",
        source,
        *args,
    )
    assert code == 0, err
    code, err = run(
        capsys, "replay", source, material / "height.npy", material / "brick_normal.png", "-o", again, "-q"
    )
    assert code == 0, err
    assert (out / "height.npy").read_bytes() == (again / "height.npy").read_bytes()
    src = np.load(source)
    expected = np.load(material / "height.npy")[src[..., 0], src[..., 1]]
    np.testing.assert_array_equal(np.load(again / "height.npy"), expected)
    assert np.array_equal(replay(src, np.load(material / "height.npy")), expected)
    with pytest.raises(InputError, match="up to row"):
        replay(src + 100, np.load(material / "height.npy"))
    write_image(tmp_path / "small.png", np.zeros((10, 10)))
    code, err = run(capsys, "replay", source, tmp_path / "small.png", "-o", tmp_path / "s.png")
    one_line_error(code, err, "the image is 10x10")
    assert not (tmp_path / "s.png").exists()


def test_replay_refuses_channels_of_different_sizes(tmp_path, material, capsys):
    """The map holds no exemplar size: a bigger channel's positions lie inside it, so the
    channels are at least checked against each other (a 64x64 albedo with a 64x60 normal)."""
    source = tmp_path / "map.npy"
    np.save(source, np.zeros((8, 8, 2), dtype=np.int32))  # every position in any channel
    write_image(tmp_path / "other.png", np.zeros((60, 64)))
    out = tmp_path / "out"
    code, err = run(capsys, "replay", source, material / "albedo.png", tmp_path / "other.png", "-o", out)
    one_line_error(code, err, "64x60")
    assert not out.exists()


def test_a_stack_is_written_again_into_its_existing_folder(tmp_path, material, capsys):
    """An existing output folder is no refusal: its files are replaced with --overwrite only."""
    out = tmp_path / "out"
    args = ["synth", material / "albedo.png", "--with", material / "rough.png", "-o", out]
    args += ["-p", "patch_size=16", "--size", "48x40", "-q"]
    code, err = run(capsys, *args, "--seed", "1")
    assert code == 0, err
    first = (out / "rough.png").read_bytes()
    code, err = run(capsys, *args, "--seed", "2")
    one_line_error(code, err, "--overwrite")
    assert (out / "rough.png").read_bytes() == first
    code, err = run(capsys, *args, "--seed", "2", "--overwrite")
    assert code == 0, err
    assert (out / "rough.png").read_bytes() != first


def test_methods_that_cannot_carry_a_stack_say_which_can(tmp_path, material, capsys):
    out = tmp_path / "out"
    code, err = run(
        capsys,
        "synth",
        material / "albedo.png",
        "--with",
        material / "height.npy",
        "-o",
        out,
        "-m",
        "portilla_simoncelli",
    )
    one_line_error(code, err, "quilting")
    assert "mslg" in err and not out.exists()  # the folder it made is removed again
    write_image(tmp_path / "other.png", np.zeros((30, 30)))
    code, err = run(capsys, "synth", material / "albedo.png", "--with", tmp_path / "other.png", "-o", out)
    one_line_error(code, err, "exemplar's size")


def test_rgba_alpha_is_carried_along_the_source_map_and_jointly():
    albedo = albedo_of(48)
    alpha = (luma(albedo) > 0.45).astype(np.float64)
    rgba = np.dstack([albedo, alpha])
    result = texsyn.synthesize_stack(rgba, method="quilting", shape=(64, 64), rng=2, patch_size=12)
    out, src = result.images[0], result.source_map
    assert out.shape == (64, 64, 4)
    np.testing.assert_array_equal(out[..., 3], alpha[src[..., 0], src[..., 1]])
    assert np.array_equal(
        texsyn.synthesize(rgba, "quilting", (64, 64), rng=2, patch_size=12), out.astype(np.float32)
    )
    joint = texsyn.synthesize(np.dstack([albedo, luma(albedo)]), "random_phase", (64, 64), rng=0)
    assert joint.shape == (64, 64, 4)  # alpha as a joint channel: the linear relation holds
    assert np.abs(joint[..., 3] - luma(joint[..., :3])).mean() < 0.01
    with pytest.warns(UserWarning, match="alpha channel is dropped"):
        grey = texsyn.synthesize(rgba, "portilla_simoncelli", (32, 32), rng=0, n_iterations=1)
    assert grey.shape == (32, 32, 3)


def test_float_exemplars_keep_their_range_and_bit_depths_follow_the_exemplar(tmp_path, material, capsys):
    height = material / "height.npy"
    code, err = run(
        capsys, "synth", height, "-o", tmp_path / "h.tif", "-m", "random_phase", "--seed", "1", "-q"
    )
    assert code == 0, err
    out = read_image_file(tmp_path / "h.tif")
    stored = np.load(height)
    assert out.bit_depth == 32 and out.pixels.dtype == np.float32
    assert stored.min() - 1e-6 <= out.pixels.min() < 0.0 < out.pixels.max() <= stored.max() + 1e-6
    assert out.pixels.std() > 0.5 * stored.std()  # not clipped to [0, 1] nor flattened
    code, err = run(capsys, "synth", height, "-o", tmp_path / "h.png", "--seed", "1")
    one_line_error(code, err, "--bit-depth 16")
    code, err = run(
        capsys, "synth", height, "-o", tmp_path / "h16.png", "--bit-depth", "16", "--seed", "1", "-q"
    )
    assert code == 0, err
    sidecar = json.loads((tmp_path / "h16.png.json").read_text())["options"]
    assert sidecar["bit_depth"] == 16 and sidecar["value_range"][0] == pytest.approx(float(stored.min()))
    code, err = run(
        capsys,
        "synth",
        material / "albedo.png",
        "-o",
        tmp_path / "a.png",
        "--size",
        "40x40",
        "--seed",
        "1",
        "-q",
    )
    assert code == 0 and read_image_file(tmp_path / "a.png").bit_depth == 16, err  # auto: 16 in, 16 out
    with pytest.raises(ImageReadError, match=r"outside \[0, 1\]"):
        read_image(height)  # read_image keeps its [0, 1] contract; read_image_file reads any range


def test_float_and_exr_files_round_trip(tmp_path):
    values = np.random.default_rng(0).normal(0.0, 3.0, (12, 10, 3)).astype(np.float32)
    write_image(tmp_path / "f.tif", values, bit_depth=32)
    np.testing.assert_array_equal(read_image_file(tmp_path / "f.tif").pixels, values)
    write_image(tmp_path / "f.npy", values, bit_depth=32)
    assert read_image_file(tmp_path / "f.npy").format == "NPY"
    with pytest.raises(ValueError, match="allows 8-bit or 16-bit"):
        write_image(tmp_path / "f.png", values, bit_depth=32)
    pytest.importorskip("OpenEXR")
    write_image(tmp_path / "f.exr", values, bit_depth=32)
    back = read_image_file(tmp_path / "f.exr")
    assert (back.format, back.bit_depth) == ("EXR", 32)
    np.testing.assert_array_equal(back.pixels, values)


def test_exr_without_its_library_is_one_line(tmp_path, monkeypatch):
    import builtins

    real = builtins.__import__

    def no_openexr(name, *args, **kwargs):
        if name == "OpenEXR":
            raise ImportError(name)
        return real(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_openexr)
    with pytest.raises(InputError, match="pip install OpenEXR"):
        write_image(tmp_path / "f.exr", np.zeros((4, 4), np.float32), bit_depth=32)
    assert list(tmp_path.iterdir()) == []


def test_icc_profiles_are_kept(tmp_path, capsys):
    from PIL import ImageCms

    icc = ImageCms.ImageCmsProfile(ImageCms.createProfile("sRGB")).tobytes()
    write_image(tmp_path / "ex.png", albedo_of(48), icc_profile=icc)
    for method, name in (
        ("quilting", "streamed.png"),
        ("random_phase", "whole.tif"),
        ("random_phase", "whole.jpg"),
    ):
        code, err = run(
            capsys, "synth", tmp_path / "ex.png", "-o", tmp_path / name, "-m", method, "--seed", "1", "-q"
        )
        assert code == 0, err
        assert read_image_file(tmp_path / name).icc_profile == icc, name
    assert read_image_file(tmp_path / "ex.png").icc_profile == icc


def test_linear_synthesises_in_linear_light(tmp_path, capsys):
    """``--linear``: the method sees the sRGB-decoded exemplar and its output is encoded
    again; without it, the method sees the stored values."""
    write_image(tmp_path / "ex.png", albedo_of(32))
    exemplar = read_image(tmp_path / "ex.png").astype(np.float64)
    outputs = {}
    for flag in ((), ("--linear",)):
        out = tmp_path / f"o{len(flag)}.png"
        code, err = run(
            capsys, "synth", tmp_path / "ex.png", "-o", out, "-m", "random_phase", "--seed", "1", "-q", *flag
        )
        assert code == 0, err
        assert json.loads(out.with_name(out.name + ".json").read_text())["options"]["linear"] is bool(flag)
        outputs[bool(flag)] = read_image(out)
    in_linear = linear_to_srgb(texsyn.synthesize(srgb_to_linear(exemplar), "random_phase", rng=1))
    np.testing.assert_allclose(outputs[True], in_linear, atol=0.51 / 255)
    stored = texsyn.synthesize(exemplar, "random_phase", rng=1)
    np.testing.assert_allclose(outputs[False], stored, atol=0.51 / 255)
    assert np.abs(outputs[True] - outputs[False]).mean() > 5 / 255


def test_layer_encoding_maps_any_range_without_clipping():
    values = np.array([[-3.0, 0.0], [2.0, 7.0]])
    code = LayerEncoding.of(values)
    assert code.to_unit(values).min() == 0.0 and code.to_unit(values).max() == 1.0
    np.testing.assert_allclose(code.from_unit(code.to_unit(values)), values)
    assert LayerEncoding.of(np.array([0.2, 0.9])).is_identity
    with pytest.raises(InputError, match="--linear"):
        LayerEncoding.of(values, linear=True)


def test_joint_methods_take_many_channels_but_not_more_than_they_allow():
    stack = np.dstack([albedo_of(32)] * 6)  # 18 channels
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(InputError, match="at most 16 channels"):
            texsyn.synthesize_stack(stack[..., :3], [stack[..., 3:6]] * 5, method="random_phase")
