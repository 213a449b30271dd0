"""Batch runs on Dask (issue 22, ``docs/batch.md``): same bytes as ``synth``, resumable, robust.

One local cluster of 2 worker processes (one thread each, no dashboard) serves the module;
the exemplars are 32x32 crops written to a temporary folder and the methods the fast ones
(quilting, which streams its rows, and random phase, which does not), so that the two ways
``synth`` writes a PNG are both checked.
"""

from __future__ import annotations

import hashlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import texsyn
from texsyn.cli import main
from texsyn.io import read_image_header, write_image
from texsyn.metrics import METRIC_DESCRIPTIONS

distributed = pytest.importorskip("distributed")

import texsyn.batch as batch  # noqa: E402
from texsyn.batch.manifest import Manifest  # noqa: E402
from texsyn.batch.tasks import ONE_THREAD_ENVIRONMENT  # noqa: E402

METHODS = ["quilting", "random_phase"]
PARAMS = {"quilting": {"patch_size": 12}}
SIZE = (40, 36)  # (height, width)


def sha(path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


@pytest.fixture(scope="module")
def cluster():
    with (
        distributed.LocalCluster(
            n_workers=2,
            threads_per_worker=1,
            processes=True,
            dashboard_address=None,
            silence_logs=50,
            env=dict(ONE_THREAD_ENVIRONMENT),
        ) as local,
        distributed.Client(local) as client,
    ):
        yield client


@pytest.fixture(scope="module")
def exemplars(tmp_path_factory):
    """Six 32x32 exemplars: grey crops of the three built-in textures, and three colour ones."""
    folder = tmp_path_factory.mktemp("exemplars")
    full = {name: texsyn.data.exemplar(name, size=None) for name in ("brick", "grass", "gravel")}
    for name, image in full.items():
        write_image(folder / f"{name}.png", image[100:132, 60:92])
    for k, (a, b, c) in enumerate(
        [("brick", "grass", "gravel"), ("grass", "gravel", "brick"), ("gravel", "brick", "grass")]
    ):
        colour = np.stack(
            [full[a][200:232, 200:232], full[b][300:332, 40:72], full[c][10:42, 400:432]], axis=-1
        )
        write_image(folder / f"colour{k}.png", colour)
    return folder


@pytest.fixture(scope="module")
def killed_run(cluster, exemplars, tmp_path_factory):
    """6 exemplars x 2 methods x 2 seeds on 2 workers, one worker killed after the first item."""
    outdir = tmp_path_factory.mktemp("batch")
    items = batch.plan([str(exemplars)], outdir, METHODS, seeds=2, size=SIZE, params=PARAMS)
    before = cluster.run(os.getpid)
    killed = []

    def kill_one(progress):
        if progress.done == 1 and not killed:
            busy = [address for address, keys in cluster.processing().items() if keys] or list(before)
            os.kill(before[busy[0]], signal.SIGKILL)
            killed.append(busy[0])

    records = batch.run(items, cluster, callback=kill_one)
    return items, records, outdir, before, killed


def test_a_batch_survives_a_killed_worker(killed_run, cluster):
    items, records, outdir, before, killed = killed_run
    assert len(items) == 6 * 2 * 2 and killed
    assert [r["id"] for r in records] == [item.id for item in items]
    assert all(r["status"] == "done" for r in records), [r["error"] for r in records]
    for item, record in zip(items, records):
        assert sha(item.output_path) == record["sha256"]
        assert record["size"] == [SIZE[1], SIZE[0]] and record["peak_memory_bytes"] > 0
    # the killed process is gone; every output comes from one of the live ones or the dead one before it died
    cluster.wait_for_workers(2, timeout=30)
    assert before[killed[0]] not in cluster.run(os.getpid).values()
    lines = (outdir / "manifest.jsonl").read_text().splitlines()
    assert len(lines) == len(items) and {json.loads(line)["id"] for line in lines} == {i.id for i in items}
    # outputs differ from one another: seeds, exemplars and methods all matter
    assert len({r["sha256"] for r in records}) == len(records)


def test_a_rerun_does_no_work(killed_run):
    items, records, outdir, _, _ = killed_run
    manifest = (outdir / "manifest.jsonl").read_bytes()
    stamps = {p: p.stat().st_mtime_ns for p in outdir.rglob("*.png")}
    connected = []
    again = batch.run(items, on_connect=connected.append)  # would start a local cluster if any work were left
    assert again.computed == 0 and not connected
    assert list(again) == list(records)
    assert (outdir / "manifest.jsonl").read_bytes() == manifest
    assert {p: p.stat().st_mtime_ns for p in outdir.rglob("*.png")} == stamps


def test_outputs_are_the_bytes_of_texsyn_synth_with_the_recorded_seed(killed_run, tmp_path):
    items, records, _, _, _ = killed_run
    for method in METHODS:  # quilting streams its rows, random phase is written whole
        item, record = next(
            (i, r) for i, r in zip(items, records) if i.method == method and "colour" in i.exemplar
        )
        args = ["synth", item.exemplar, "-m", method, "--seed", str(record["seed"]), "--size", "36x40", "-q"]
        args += [f"-p{k}={v}" for k, v in PARAMS.get(method, {}).items()]
        out = tmp_path / f"{method}.png"
        assert main([*args, "-o", str(out)]) == 0
        assert sha(out) == record["sha256"] == sha(item.output_path)


def test_outputs_do_not_depend_on_the_number_of_workers(killed_run, exemplars, tmp_path):
    items, records, _, _, _ = killed_run
    # the same batch in another folder, listed in another order, on a new local cluster of one worker
    shuffled = [str(p) for p in sorted(exemplars.iterdir(), reverse=True)]
    alone = batch.plan(shuffled, tmp_path, list(reversed(METHODS)), seeds=2, size=SIZE, params=PARAMS)
    one = batch.run(alone, workers=1)
    by_output = {r["output"]: r for r in records}
    assert len(one) == len(records)
    # one fit per (exemplar, method), shared by its items: they record the same fit time
    fits: dict[str, set] = {}
    for item, record in zip(alone, one):
        fits.setdefault(item.fit_key, set()).add(record["fit_seconds"])
    assert len(fits) == 6 * 2 and all(len(seconds) == 1 for seconds in fits.values())
    for record in one:
        assert record["sha256"] == by_output[record["output"]]["sha256"]
        assert record["seed"] == by_output[record["output"]]["seed"]


def test_seeds_come_from_the_batch_seed_and_the_item_alone(exemplars, tmp_path):
    image = str(exemplars / "brick.png")
    items = batch.plan([image], tmp_path, ["quilting"], seeds=3)
    digest = hashlib.sha256(Path(image).read_bytes()).hexdigest()
    for k, item in enumerate(items):
        text = f"texsyn-batch-seed/1\n0\n{digest}\nquilting\n{k}".encode()
        assert item.seed == int.from_bytes(hashlib.sha256(text).digest()[:8], "big") >> 1
        assert item.output == f"brick/quilting-s{item.seed}.png" and item.seed_index == k
    assert len({i.seed for i in items}) == 3
    other = batch.plan([image], tmp_path, ["quilting"], seeds=3, batch_seed=1)
    assert {i.seed for i in other}.isdisjoint({i.seed for i in items})
    explicit = batch.plan([image], tmp_path, ["quilting"], seed_list=[7, 3])
    assert [(i.seed, i.batch_seed) for i in explicit] == [(7, None), (3, None)]


def test_inputs_with_the_same_name_are_refused(exemplars, tmp_path):
    (tmp_path / "other").mkdir()
    write_image(tmp_path / "other" / "brick.jpg", texsyn.data.exemplar("grass", size=32))
    with pytest.raises(texsyn.errors.InputError, match="same name 'brick'"):
        batch.plan([str(exemplars), str(tmp_path / "other")], tmp_path / "out", ["quilting"])
    with pytest.raises(texsyn.errors.InputError, match="matches no image"):
        batch.plan([str(tmp_path / "nothing*.png")], tmp_path / "out", ["quilting"])


def test_a_failed_item_is_recorded_and_the_others_are_made(cluster, exemplars, tmp_path, capsys):
    folder = tmp_path / "in"
    folder.mkdir()
    (folder / "broken.png").write_bytes(b"not an image at all")
    write_image(folder / "good.png", texsyn.data.exemplar("brick", size=32))
    address = cluster.scheduler.address
    args = ["batch", str(folder), "-o", str(tmp_path / "out"), "-m", "random_phase", "--size", "20x20"]
    assert main([*args, "--scheduler", address, "-q"]) == 1
    err = capsys.readouterr().err
    assert "1 failed" in err and "broken" in err
    records = [json.loads(line) for line in (tmp_path / "out" / "manifest.jsonl").read_text().splitlines()]
    assert sorted(r["status"] for r in records) == ["done", "failed"]
    failed = next(r for r in records if r["status"] == "failed")
    assert "fit failed" in failed["error"] and failed["sha256"] is None
    assert (tmp_path / "out" / "good").is_dir() and not (tmp_path / "out" / "broken").exists()


def test_a_changed_output_is_made_again_only_with_overwrite(cluster, exemplars, tmp_path):
    items = batch.plan([str(exemplars / "grass.png")], tmp_path, ["random_phase"], size=(24, 24))
    first = batch.run(items, cluster)
    path = items[0].output_path
    good = path.read_bytes()
    path.write_bytes(good[:-1] + bytes([good[-1] ^ 1]))  # not the checksum the manifest holds
    kept = batch.run(items, cluster)
    assert kept.computed == 1 and kept[0]["status"] == "failed" and "--overwrite" in kept[0]["error"]
    assert path.read_bytes() != good
    redone = batch.run(items, cluster, overwrite=True)
    assert redone[0]["status"] == "done" and path.read_bytes() == good
    assert redone[0]["sha256"] == first[0]["sha256"]
    # an output written before the run stopped, but not recorded, is kept: it is the item's
    (tmp_path / "manifest.jsonl").unlink()
    adopted = batch.run(items, cluster)
    assert adopted[0]["status"] == "done" and adopted[0]["adopted"] and path.read_bytes() == good


def test_peak_memory_is_the_items_own(cluster, exemplars, tmp_path):
    small, large = (
        batch.plan([str(exemplars / "gravel.png")], tmp_path / name, ["random_phase"], size=size)
        for name, size in (("small", (24, 24)), ("large", (1536, 1536)))
    )
    peaks = [
        batch.run(items, cluster)[0] for items in (large, small)
    ]  # the large first: the small's peak is its own
    assert [p["peak_memory_scope"] for p in peaks] == ["item", "item"]
    assert peaks[0]["peak_memory_bytes"] > peaks[1]["peak_memory_bytes"] + 1536 * 1536 * 8


def test_a_manifest_line_cut_short_is_skipped_and_the_next_record_starts_a_line(tmp_path):
    (tmp_path / "manifest.jsonl").write_text('{"id": "a", "status": "done"}\n{"id": "b", "sta')
    with Manifest(tmp_path) as manifest:
        assert set(manifest.read()) == {"a"} and manifest.skipped_lines == 1
        manifest.append({"id": "c", "status": "failed", "x": float("nan")})
        with pytest.raises(texsyn.errors.InputError, match="another texsyn batch"), Manifest(tmp_path):
            pass
    again = Manifest(tmp_path).read()
    assert set(again) == {"a", "c"} and again["c"]["x"] is None


def test_bytes_mode_writes_the_same_files(killed_run, cluster, tmp_path):
    items, records, _, _, _ = killed_run
    chosen = [i for i in items if i.exemplar.endswith("colour1.png")]
    moved = batch.plan([chosen[0].exemplar], tmp_path, METHODS, seeds=2, size=SIZE, params=PARAMS)
    sent = batch.run(moved, cluster, send_bytes=True)
    expected = {r["output"]: r["sha256"] for r in records}
    assert [r["sha256"] for r in sent] == [expected[r["output"]] for r in sent]
    assert all(sha(i.output_path) == r["sha256"] for i, r in zip(moved, sent))
    frame = pytest.importorskip("pandas") and sent.to_dataframe()
    assert len(frame) == 4 and list(frame["sha256"]) == [r["sha256"] for r in sent]


def test_the_batch_command(cluster, exemplars, tmp_path, capsys):
    address = cluster.scheduler.address
    out = tmp_path / "out"
    args = [
        "batch",
        str(exemplars / "b*.png"),
        str(exemplars / "grass.png"),
        "-o",
        str(out),
        "-m",
        "random_phase",
    ]
    args += ["--seed-list", "5,9", "--size", "20x16", "--scheduler", address]
    assert main(args) == 0
    err = capsys.readouterr().err
    assert "4 items" in err and "4 made" in err and f"Dask scheduler {address}" in err
    assert sorted(str(p.relative_to(out)) for p in out.rglob("*.png")) == [
        "brick/random_phase-s5.png",
        "brick/random_phase-s9.png",
        "grass/random_phase-s5.png",
        "grass/random_phase-s9.png",
    ]
    assert main([*args, "-q"]) == 0
    assert capsys.readouterr().err == ""
    assert len((out / "manifest.jsonl").read_text().splitlines()) == 4
    # usage errors and bad input stop before any work, with one line and exit status 2
    for wrong, message in [
        (["--seeds", "2", "--seed-list", "1"], "--seeds or --seed-list"),
        (["--workers", "2"], "--workers sizes the local cluster"),
        (["-p", "quilting.patch_size=8"], "not among the methods"),
        (["-m", "nope"], "nope"),
    ]:
        assert main([*args, *wrong, "-o", str(tmp_path / "never")]) == 2
        line = capsys.readouterr().err
        assert line.startswith("texsyn: error:") and message in line and line.count("\n") == 1
    assert not (tmp_path / "never").exists()


def test_compare_over_a_folder(cluster, exemplars, tmp_path, capsys):
    report = tmp_path / "report.html"
    args = [
        "compare",
        "--batch",
        str(exemplars / "g*.png"),
        "-o",
        str(report),
        "-m",
        "random_phase",
        "-m",
        "quilting",
    ]
    args += [
        "-p",
        "quilting.patch_size=12",
        "--seeds",
        "2",
        "--size",
        "36x40",
        "--scheduler",
        cluster.scheduler.address,
    ]
    assert main([*args, "-q"]) == 0
    data = json.loads(report.with_suffix(".json").read_text())
    assert [s["method"] for s in data["summary"]] == ["random_phase", "quilting"]
    assert [e["exemplar"] for e in data["exemplars"]] == [
        str(exemplars / "grass.png"),
        str(exemplars / "gravel.png"),
    ]
    for summary in data["summary"]:
        runs = [
            run
            for e in data["exemplars"]
            for m in e["methods"]
            if m["method"] == summary["method"]
            for run in m["runs"]
        ]
        assert summary["done"] == 4 and [r["seed"] for r in runs] == [0, 1, 0, 1]
        assert set(summary["mean_metrics"]) == set(METRIC_DESCRIPTIONS)
        for name, mean in summary["mean_metrics"].items():
            assert mean == pytest.approx(np.mean([r["metrics"][name] for r in runs]))
    page = report.read_text()
    assert page.count("<table>") == 1 + 2 and page.count("<img ") == 2 * 2 * 2
    assert 'src="report_files/grass/quilting-s0.png"' in page
    # the compare outputs are the synth outputs of seeds 0 and 1
    assert (
        main(
            [
                "synth",
                str(exemplars / "grass.png"),
                "-m",
                "random_phase",
                "--seed",
                "1",
                "--size",
                "36x40",
                "-q",
                "-o",
                str(tmp_path / "s.png"),
            ]
        )
        == 0
    )
    assert sha(tmp_path / "s.png") == sha(tmp_path / "report_files" / "grass" / "random_phase-s1.png")
    assert (
        main(
            [
                "compare",
                str(exemplars / "grass.png"),
                str(exemplars / "gravel.png"),
                "-o",
                str(tmp_path / "x.html"),
            ]
        )
        == 2
    )
    assert "--batch" in capsys.readouterr().err


def test_importing_texsyn_and_texsyn_batch_does_not_load_dask():
    code = "import texsyn, texsyn.batch, sys; print(sorted(m for m in sys.modules if m.split('.')[0] in ('dask', 'distributed')))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


@pytest.mark.slow
def test_ctrl_c_stops_cleanly_and_the_rerun_finishes(exemplars, tmp_path):
    out = tmp_path / "out"
    args = [sys.executable, "-m", "texsyn.cli", "batch", str(exemplars), "-o", str(out), "-m", "quilting"]
    args += ["-p", "quilting.patch_size=12", "--seeds", "4", "--size", "64x64", "--workers", "1", "-q"]
    process = subprocess.Popen(args, stderr=subprocess.PIPE, text=True)
    manifest = out / "manifest.jsonl"
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and not (manifest.exists() and manifest.read_text().count("\n") >= 2):
        time.sleep(0.05)
    process.send_signal(signal.SIGINT)
    _, err = process.communicate(timeout=60)
    assert process.returncode == 130 and "interrupted" in err
    finished = [json.loads(line) for line in manifest.read_text().splitlines()]
    assert 2 <= len(finished) < 24 and all(r["status"] == "done" for r in finished)
    done = subprocess.run(args, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert len(manifest.read_text().splitlines()) == 24
    assert len(list(out.rglob("*.png"))) == 24


def test_a_pattern_over_the_output_folder_does_not_take_the_outputs_for_exemplars(exemplars, tmp_path):
    write_image(tmp_path / "brick.png", texsyn.data.exemplar("brick", size=32))
    made = tmp_path / "out" / "brick" / "random_phase-s1.png"  # what an earlier run left
    made.parent.mkdir(parents=True)
    made.write_bytes((tmp_path / "brick.png").read_bytes())
    items = batch.plan([str(tmp_path / "**" / "*.png")], tmp_path / "out", ["random_phase"])
    assert [i.exemplar for i in items] == [str(tmp_path / "brick.png")]
    # the output folder may be the input folder itself: its own images are exemplars
    alone = batch.plan([str(exemplars)], exemplars, ["random_phase"])
    assert len(alone) == 6


def test_compare_batch_overwrite_replaces_the_outputs_of_other_parameters(
    cluster, exemplars, tmp_path, capsys
):
    args = ["compare", "--batch", str(exemplars / "grass.png"), "-o", str(tmp_path / "r.html"), "-q"]
    args += ["-m", "random_phase", "--scheduler", cluster.scheduler.address]
    assert main([*args, "--size", "16x16"]) == 0
    assert main([*args, "--size", "20x16"]) == 2  # the report exists
    assert main([*args, "--size", "20x16", "--overwrite"]) == 0, capsys.readouterr().err
    data = json.loads((tmp_path / "r.json").read_text())
    assert [s["done"] for s in data["summary"]] == [1]


def test_a_scheduler_address_that_is_not_one_is_one_line(tmp_path, capsys):
    args = ["batch", "builtin:brick", "-o", str(tmp_path / "out"), "-m", "random_phase", "-q"]
    assert main([*args, "--scheduler", "not-an-address"]) == 2
    line = capsys.readouterr().err
    assert line.startswith("texsyn: error: cannot reach the Dask scheduler") and line.count("\n") == 1


def test_an_error_of_the_batch_on_a_scheduler_is_not_taken_for_the_connection(
    cluster, exemplars, tmp_path, monkeypatch
):
    def full_disk(self, record):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(Manifest, "append", full_disk)
    items = batch.plan([str(exemplars / "brick.png")], tmp_path, ["random_phase"], size=(16, 16))
    with pytest.raises(OSError, match="No space left"):
        batch.run(items, scheduler=cluster.scheduler.address)


def test_an_output_that_would_replace_an_input_is_refused(tmp_path):
    """A previous output given back as an input, with the seed that made it: the batch would
    write over its own exemplar (found by the issue-22 review)."""
    folder = tmp_path / "out" / "quilting-s3"
    folder.mkdir(parents=True)
    exemplar = folder / "quilting-s3.png"
    write_image(exemplar, texsyn.data.exemplar("brick", size=32))
    with pytest.raises(texsyn.errors.InputError, match="would replace the input"):
        batch.plan([str(exemplar)], tmp_path / "out", ["quilting"], seed_list=[3])


def test_an_output_folder_below_a_file_is_a_one_line_input_error(tmp_path, capsys):
    (tmp_path / "afile").write_text("not a folder")
    exemplar = tmp_path / "ex.png"
    write_image(exemplar, texsyn.data.exemplar("brick", size=32))
    code = main(
        [
            "batch",
            str(exemplar),
            "-o",
            str(tmp_path / "afile" / "sub"),
            "-m",
            "random_phase",
            "--workers",
            "1",
        ]
    )
    err = capsys.readouterr().err
    assert code == 2 and "cannot be made" in err and err.count("\n") == 1


def test_a_16_bit_exemplar_gives_the_16_bit_output_of_texsyn_synth(cluster, tmp_path):
    """synth writes at the exemplar's bit depth by default (issue 23): a batch item too."""
    rng = np.random.default_rng(2)
    folder = tmp_path / "in"
    folder.mkdir()
    deep = np.kron(rng.random((8, 8, 3)), np.ones((4, 4, 1)))  # 32x32, 16-bit levels
    write_image(folder / "deep.png", deep, bit_depth=16)
    write_image(folder / "alpha.png", np.dstack([deep, np.ones((32, 32))]))
    np.save(folder / "height.npy", (3.0 * deep[..., 0]).astype(np.float32))
    items = batch.plan(
        [str(folder / "deep.png"), str(folder / "alpha.png"), str(folder / "height.npy")],
        tmp_path / "out",
        ["random_phase"],
        size=(36, 40),  # (height, width): --size 40x36,
    )
    records = {Path(r["exemplar"]).name: r for r in batch.run(items, client=cluster)}
    done = records["deep.png"]
    assert done["status"] == "done"
    produced = tmp_path / "out" / done["output"]
    assert read_image_header(produced).bit_depth == 16
    out = tmp_path / "synth.png"
    assert (
        main(
            [
                "synth",
                str(folder / "deep.png"),
                "-m",
                "random_phase",
                "--seed",
                str(done["seed"]),
                "--size",
                "40x36",
                "-q",
                "-o",
                str(out),
            ]
        )
        == 0
    )
    assert sha(out) == done["sha256"] == sha(produced)
    assert records["alpha.png"]["status"] == "failed" and "alpha channel" in records["alpha.png"]["error"]
    assert records["height.npy"]["status"] == "failed" and "floating-point" in records["height.npy"]["error"]
