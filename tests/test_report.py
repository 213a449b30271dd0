"""The comparison report: data, HTML, JSON sidecar, the compare command and a browser check."""

import json
import os
import subprocess

import pytest

import texsyn
from browser_utils import CHROMIUM_FLAGS, find_chromium
from conftest import FAST_PARAMS
from texsyn.cli import main
from texsyn.report import run_comparison, write_report


@pytest.fixture(scope="module")
def report(request):
    ex = texsyn.data.exemplar("gravel", size=32)
    params = {name: FAST_PARAMS[name] for name in texsyn.METHODS}
    params["quilting"] = {"patch_size": 12}
    return run_comparison(ex, seeds=2, shape=(40, 36), exemplar_name="gravel", params=params)


def test_report_records_every_method_and_seed(report):
    assert [r.method for r in report.records] == sorted(texsyn.METHODS)
    for rec in report.records:
        assert rec.error is None
        assert [run.seed for run in rec.runs] == [0, 1]
        for run in rec.runs:
            assert run.image.shape == (40, 36)
            assert run.map_image.shape == (40, 36, 3)
            assert set(run.metrics) == set(texsyn.metrics.METRIC_DESCRIPTIONS)
            assert run.seconds > 0
        expected = "method's source map" if texsyn.METHODS[rec.method].has_source_map else "nearest patches"
        assert rec.runs[0].map_source == expected
    quilting = next(r for r in report.records if r.method == "quilting")
    assert quilting.params["patch_size"] == 12


def test_html_is_self_contained_and_json_is_complete(report, tmp_path):
    html_path, json_path = write_report(report, tmp_path / "r.html")
    page = html_path.read_text()
    n_runs = sum(len(r.runs) for r in report.records)
    assert page.count('src="data:image/png;base64,') == 2 + 2 * n_runs
    assert "http://" not in page and "https://" not in page
    data = json.loads(json_path.read_text())
    assert data["versions"]["texsyn"] == texsyn.__version__
    assert {m["method"] for m in data["methods"]} == set(texsyn.METHODS)
    for m in data["methods"]:
        assert m["median_seconds"] > 0 and len(m["runs"]) == 2
    with pytest.raises(FileExistsError, match="overwrite"):
        write_report(report, tmp_path / "r.html")
    write_report(report, tmp_path / "r.html", overwrite=True)


def test_a_failing_method_is_reported_and_the_others_still_run():
    ex = texsyn.data.exemplar("brick", size=20)
    rep = run_comparison(ex, ["quilting", "random_phase"], shape=(24, 24))  # patch 32 > 20
    quilting, rphase = rep.records
    assert quilting.error and "too small" in quilting.error and not quilting.runs
    assert rphase.error is None and len(rphase.runs) == 1
    assert "failed" in rep.to_html()


def test_compare_command(tmp_path, capsys):
    out = tmp_path / "cmp.html"
    args = [
        "compare",
        "builtin:grass",
        "-o",
        str(out),
        "-m",
        "quilting",
        "-m",
        "random_phase",
        "--size",
        "48x40",
        "-p",
        "quilting.patch_size=16",
        "-q",
    ]
    assert main(args) == 0
    data = json.loads(out.with_suffix(".json").read_text())
    assert [m["method"] for m in data["methods"]] == ["quilting", "random_phase"]
    assert data["output_shape"] == [40, 48]
    capsys.readouterr()
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "already exists" in err and len(err.strip().splitlines()) == 1
    assert main(args + ["--overwrite"]) == 0
    assert main(["compare", "-o", str(tmp_path / "x.html"), "-m", "nope"]) == 2
    assert main(["compare", "-o", str(tmp_path / "x.html"), "-p", "patch_size=3"]) == 2
    assert not (tmp_path / "x.html").exists()


CHECK_IMAGES = """
<script>
window.addEventListener('load', function () {
  var imgs = Array.prototype.slice.call(document.images);
  var ok = imgs.filter(function (i) { return i.complete && i.naturalWidth > 0; }).length;
  document.body.setAttribute('data-images-loaded', ok + '/' + imgs.length);
});
</script>
"""


def chromium_args(binary, tmp_path):
    return [
        binary,
        "--headless",
        *CHROMIUM_FLAGS,
        f"--user-data-dir={tmp_path / 'profile'}",
        "--virtual-time-budget=5000",
    ]


@pytest.mark.skipif(
    find_chromium() is None, reason="headless Chromium is not installed (Debian package 'chromium')"
)
def test_report_opens_in_a_browser_with_every_image_loaded(report, tmp_path):
    html_path, _ = write_report(report, tmp_path / "report.html")
    probe = tmp_path / "probe.html"
    probe.write_text(html_path.read_text().replace("</body>", CHECK_IMAGES + "</body>"))
    binary = find_chromium()
    dom = subprocess.run(
        chromium_args(binary, tmp_path) + ["--dump-dom", probe.as_uri()],
        capture_output=True,
        text=True,
        timeout=120,
    ).stdout
    n_images = 2 + 2 * sum(len(r.runs) for r in report.records)
    assert f'data-images-loaded="{n_images}/{n_images}"' in dom
    shots = os.environ.get("TEXSYN_TEST_ARTIFACTS", str(tmp_path))
    os.makedirs(shots, exist_ok=True)
    shot = os.path.join(shots, "report_screenshot.png")
    subprocess.run(
        chromium_args(binary, tmp_path)
        + ["--window-size=1200,1600", f"--screenshot={shot}", html_path.as_uri()],
        capture_output=True,
        timeout=120,
    )
    with open(shot, "rb") as fh:
        assert fh.read(8) == b"\x89PNG\r\n\x1a\n"
    assert os.path.getsize(shot) > 10_000
