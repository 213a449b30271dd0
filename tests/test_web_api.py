"""``texsyn serve``'s HTTP API with httpx against a real server (issue 21): every endpoint,
hostile input, the Host/Origin/token guard, the queue, cancel and timeouts."""

from __future__ import annotations

import io
import json
import struct
import zlib

import numpy as np
import pytest

pytest.importorskip("fastapi")
pytest.importorskip("uvicorn")

from texsyn.cli import main
from texsyn.io import write_image
from web_utils import live_server, wait_for


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    with live_server(tmp_path_factory.mktemp("serve"), workers=2, queue_limit=4) as live:
        yield live


@pytest.fixture(scope="module")
def client(server):
    with server.client() as c:
        yield c


@pytest.fixture(scope="module")
def png_bytes(tmp_path_factory) -> bytes:
    rng = np.random.default_rng(3)
    base = rng.random((12, 12, 3))
    image = np.kron(base, np.ones((4, 4, 1)))[:40, :40]  # blocky, so quilting has structure
    path = tmp_path_factory.mktemp("png") / "blocks.png"
    write_image(path, image)
    return path.read_bytes()


@pytest.fixture(scope="module")
def uploaded(client, png_bytes) -> dict:
    response = client.post("/api/exemplars", content=png_bytes, headers={"X-Filename": "my%20blocks.png"})
    assert response.status_code == 201, response.text
    return response.json()


def png_header_only(width: int, height: int) -> bytes:
    """A PNG whose header declares ``width x height`` and whose data is one empty row."""

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", ihdr)
        + chunk(b"IDAT", zlib.compress(b"\0"))
        + chunk(b"IEND", b"")
    )


# ------------------------------------------------------------------ the guard
def test_the_page_needs_the_token_and_says_how_to_get_it(server):
    with server.client(headers={"X-Texsyn-Token": ""}) as anonymous:
        response = anonymous.get("/")
        assert response.status_code == 401
        assert "token" in response.json()["error"]
        assert anonymous.get("/", params={"token": server.settings.token}).status_code == 200
        assert anonymous.get("/api/methods", params={"token": "wrong"}).status_code == 401
        # the static files hold nothing of the user's: no token needed
        assert anonymous.get("/static/app.js").status_code == 200


@pytest.mark.parametrize("host", ["evil.example:8000", "attacker.test", "127.0.0.1:1"])
def test_a_wrong_host_header_is_refused_dns_rebinding(client, host):
    response = client.get("/api/methods", headers={"Host": host})
    assert response.status_code == 421
    assert "Host" in response.json()["error"]


def test_a_foreign_origin_is_refused_even_with_the_token(client, png_bytes):
    for method, path in (("get", "/api/methods"), ("post", "/api/exemplars")):
        response = client.request(method, path, content=png_bytes, headers={"Origin": "http://evil.example"})
        assert response.status_code == 403
        assert "cross-site" in response.json()["error"]
    same = client.get(
        "/api/methods", headers={"Origin": client.base_url.scheme + "://" + client.base_url.netloc.decode()}
    )
    assert same.status_code == 200


def test_security_headers_on_every_response(client):
    response = client.get("/")
    assert response.headers["x-frame-options"] == "SAMEORIGIN"
    assert response.headers["referrer-policy"] == "no-referrer"
    assert "script-src 'self'" in response.headers["content-security-policy"]


# ------------------------------------------------------------------ registry and exemplars
def test_methods_lists_every_method_with_the_parameter_specs_of_the_registry(client):
    from texsyn.methods import METHODS

    body = client.get("/api/methods").json()
    names = [m["name"] for m in body["methods"]]
    assert sorted(names) == sorted(METHODS)
    quilting = next(m for m in body["methods"] if m["name"] == "quilting")
    specs = METHODS["quilting"].param_specs()
    assert [p["name"] for p in quilting["params"]] == list(specs)
    patch = next(p for p in quilting["params"] if p["name"] == "patch_size")
    assert patch["type"] == "int" and patch["default"] == str(specs["patch_size"].default)
    assert patch["allowed"]["low"] == specs["patch_size"].allowed.low
    assert patch["help"] == specs["patch_size"].description
    assert quilting["has_source_map"] is True
    assert body["limits"]["max_upload_bytes"] == 20_000_000


def test_builtin_exemplars_and_their_previews(client):
    items = client.get("/api/exemplars/builtin").json()["exemplars"]
    assert [i["id"] for i in items] == ["builtin:brick", "builtin:grass", "builtin:gravel"]
    preview = client.get(f"/api/exemplars/{items[0]['id']}/preview")
    assert preview.status_code == 200 and preview.content[:8] == b"\x89PNG\r\n\x1a\n"


def test_upload_keeps_only_a_clean_display_name_and_a_server_made_file(server, client, png_bytes):
    response = client.post(
        "/api/exemplars", content=png_bytes, headers={"X-Filename": "..%2F..%2Fetc%2Fpasswd"}
    )
    assert response.status_code == 201
    item = response.json()
    assert item["name"] == "passwd" and (item["width"], item["height"]) == (40, 40)
    assert "/" not in item["id"] and item["id"].startswith("u")
    stored = sorted(p.name for p in (server.folder / "uploads").iterdir())
    assert all(name.startswith(("u", "builtin-")) for name in stored)
    assert client.get(f"/api/exemplars/{item['id']}/preview").status_code == 200


@pytest.mark.parametrize(
    "content, status, words",
    [
        (b"", 400, "empty"),
        (b"hello, this is not an image at all", 415, "allowed types"),
        (b"%PDF-1.4 a pdf", 415, "allowed types"),
    ],
)
def test_uploads_that_are_not_images_get_one_line(client, content, status, words):
    response = client.post("/api/exemplars", content=content, headers={"X-Filename": "x.png"})
    assert response.status_code == status
    message = response.json()["error"]
    assert words in message and "\n" not in message


def test_a_truncated_png_is_refused_without_naming_a_server_path(server, client, png_bytes):
    response = client.post(
        "/api/exemplars", content=png_bytes[: len(png_bytes) // 2], headers={"X-Filename": "cut.png"}
    )
    assert response.status_code == 400
    message = response.json()["error"]
    assert "cut.png" in message and str(server.folder) not in message


def test_too_many_pixels_are_refused_from_the_header(client):
    response = client.post(
        "/api/exemplars", content=png_header_only(20000, 20000), headers={"X-Filename": "bomb.png"}
    )
    assert response.status_code == 413
    assert "pixels" in response.json()["error"]


def test_an_upload_over_the_limit_is_refused_and_the_server_keeps_serving(server, client):
    big = io.BytesIO(b"\x89PNG\r\n\x1a\n" + bytes(30_000_000))
    response = client.post("/api/exemplars", content=big.getvalue())
    assert response.status_code == 413
    assert "20 MB upload limit" in response.json()["error"]
    assert not any(p.suffix == ".part" for p in (server.folder / "uploads").iterdir())
    assert client.get("/api/methods").status_code == 200


def test_an_upload_without_a_length_is_cut_at_the_limit(tmp_path, png_bytes):
    with live_server(tmp_path, max_upload_bytes=1000) as small, small.client() as c:

        def chunks():
            for _ in range(100):
                yield bytes(100)

        response = c.post("/api/exemplars", content=chunks())
        assert response.status_code == 413
        assert "0.001 MB upload limit" in response.json()["error"]


# ------------------------------------------------------------------ jobs
def test_a_synthesis_job_gives_the_bytes_of_texsyn_synth_and_its_downloads(
    client, uploaded, png_bytes, tmp_path
):
    request = {
        "mode": "synth",
        "exemplar": uploaded["id"],
        "method": "quilting",
        "size": [64, 48],
        "seed": 11,
    }
    request["params"] = {"patch_size": "16"}
    created = client.post("/api/jobs", json=request)
    assert created.status_code == 201, created.text
    job = wait_for(client, created.json()["id"])
    assert job["state"] == "done", job
    assert set(job["files"]) == {"image", "map", "map_array", "run"}
    image = client.get(job["files"]["image"]["url"])
    assert image.headers["content-disposition"].startswith("attachment")
    assert "texsyn-quilting-11.png" in image.headers["content-disposition"]
    exemplar = tmp_path / "my blocks.png"
    exemplar.write_bytes(png_bytes)
    cli = ["synth", str(exemplar), "-m", "quilting", "--size", "64x48", "--seed", "11", "-p", "patch_size=16"]
    assert main([*cli, "-q", "-o", str(tmp_path / "cli.png")]) == 0
    assert image.content == (tmp_path / "cli.png").read_bytes()
    assert job["command_line"] == (
        "texsyn synth 'my blocks.png' -m quilting --size 64x48 --seed 11 -p patch_size=16 "
        "--source-map texsyn-quilting-11-map.npy -o texsyn-quilting-11.png"
    )
    run = client.get(job["files"]["run"]["url"]).json()
    assert run["method"] == "quilting" and run["seed"] == 11 and run["params"]["patch_size"] == 16
    assert run["command_line"] == job["command_line"] and run["inputs"] == {"exemplar": "my blocks.png"}
    source = np.load(io.BytesIO(client.get(job["files"]["map_array"]["url"]).content))
    assert source.shape == (48, 64, 2) and source.max() < 40
    assert job["metrics"]["map_source"] == "the method's source map"
    assert 0 <= job["metrics"]["values"]["copied_share"] <= 1
    assert client.get(job["files"]["map"]["url"]).content[:4] == b"\x89PNG"


def test_the_event_stream_reports_progress_until_the_job_ends(client):
    request = {
        "exemplar": "builtin:brick",
        "method": "random_phase",
        "size": [64, 64],
        "seed": 1,
        "metrics": False,
    }
    job = client.post("/api/jobs", json=request).json()
    states = []
    with client.stream("GET", f"/api/jobs/{job['id']}/events") as response:
        assert response.headers["content-type"].startswith("text/event-stream")
        for line in response.iter_lines():
            if line.startswith("data: "):
                states.append(json.loads(line[6:])["state"])
    assert states[-1] == "done" and "running" in states
    assert set(client.get(f"/api/jobs/{job['id']}").json()["files"]) == {"image", "run"}  # not measured


@pytest.mark.parametrize(
    "request_body, words",
    [
        ({"mode": "synth", "exemplar": "builtin:brick", "method": "nope"}, "unknown method"),
        ({"mode": "draw", "exemplar": "builtin:brick"}, "mode must be one of"),
        ({"exemplar": "builtin:brick", "params": {"patch_size": "x" * 5000}}, "must be a short text"),
        (
            {"exemplar": "builtin:brick", "params": {"patch_size": "0"}},
            "parameter 'patch_size' of method 'quilting' must be in",
        ),
        ({"exemplar": "builtin:brick", "params": {"--overwrite": "1"}}, "unknown parameter"),
        ({"exemplar": "builtin:brick", "params": ["patch_size=3"]}, "must be an object"),
        ({"exemplar": "builtin:brick", "size": "256x256"}, "size must be [width, height]"),
        ({"exemplar": "builtin:brick", "size": [10**9, 5]}, "the output width must be in"),
        ({"exemplar": "builtin:brick", "seed": -1}, "seed must be in"),
        ({"exemplar": "builtin:brick", "seed": 1.5}, "seed must be a whole number"),
        ({"exemplar": "builtin:brick", "seed": True}, "seed must be a whole number"),
        ({"exemplar": "../../etc/passwd"}, "unknown exemplar"),
        ({"exemplar": "builtin:../../x"}, "unknown built-in exemplar"),
        ({"exemplar": 12}, "exemplar must be"),
        ({"exemplar": "builtin:brick", "output": "/etc/passwd"}, "unknown field"),
        ({"exemplar": "builtin:brick", "metrics": "yes"}, "metrics must be true or false"),
        ({"mode": "compare", "exemplar": "builtin:brick", "methods": []}, "methods must be a list"),
        ({"mode": "animate", "exemplar": "builtin:brick", "frames": 10**6}, "frames must be in"),
        ([1, 2, 3], "must be a JSON object"),
    ],
)
def test_bad_job_requests_get_the_command_lines_one_line(client, request_body, words):
    response = client.post("/api/jobs", json=request_body)
    assert response.status_code in (404, 422), response.text
    message = response.json()["error"]
    assert words in message and "\n" not in message and "Traceback" not in message


def test_a_huge_or_broken_request_body_is_refused(client):
    assert client.post("/api/jobs", content=b"{" + b" " * 100_000).status_code == 413
    response = client.post("/api/jobs", content=b"\xff\xfe not json")
    assert response.status_code == 400 and "JSON" in response.json()["error"]
    response = client.post("/api/jobs", content=b"[" * 50_000)  # nested deeper than Python recurses
    assert response.status_code == 400 and "JSON" in response.json()["error"]


def test_the_largest_side_holds_for_the_default_output_size(tmp_path):
    with live_server(tmp_path, max_side=200) as small, small.client() as c:
        for mode in ("synth", "compare"):  # twice the 128x128 brick: 256x256
            request = {"mode": mode, "exemplar": "builtin:brick", "methods": ["random_phase"]}
            request = {k: v for k, v in request.items() if mode == "compare" or k != "methods"}
            response = c.post("/api/jobs", json=request)
            assert response.status_code == 422, response.text
            assert "default output (256x256) is over the largest side 200" in response.json()["error"]
        animated = c.post("/api/jobs", json={"mode": "animate", "exemplar": "builtin:brick", "frames": 2})
        assert animated.status_code == 201, animated.text  # frames keep the exemplar's 128x128
        c.post(f"/api/jobs/{animated.json()['id']}/cancel")


def test_an_error_of_the_command_line_reaches_the_page_as_its_one_line(client):
    # too large a patch for the 128x128 exemplar: the method refuses it when it runs
    request = {
        "exemplar": "builtin:brick",
        "method": "quilting",
        "size": [64, 64],
        "params": {"patch_size": "1000"},
    }
    job = wait_for(client, client.post("/api/jobs", json=request).json()["id"])
    assert job["state"] == "failed"
    assert "patch" in job["error"] and "\n" not in job["error"] and "texsyn-serve" not in job["error"]


def test_files_are_reached_by_key_only(client, uploaded):
    job = client.post(
        "/api/jobs", json={"exemplar": uploaded["id"], "size": [32, 32], "seed": 2, "metrics": False}
    ).json()
    job = wait_for(client, job["id"])
    for key in ("../texture.png", "texture.png", "..%2Ftexture.png", "metrics"):
        assert client.get(f"/api/jobs/{job['id']}/files/{key}").status_code == 404
    assert client.get("/api/jobs/../../etc/passwd").status_code == 404
    assert client.get("/api/jobs/jnothing").status_code == 404


def test_compare_and_animate_jobs(client):
    compare = {
        "mode": "compare",
        "exemplar": "builtin:brick",
        "methods": ["random_phase", "heeger_bergen"],
        "size": [48, 48],
    }
    compare["params"] = {"heeger_bergen": {"n_iterations": "2"}}
    animate = {"mode": "animate", "exemplar": "builtin:brick", "frames": 4, "size": [48, 48], "seed": 3}
    animate["params"] = {"n_iterations": "5"}
    first = client.post("/api/jobs", json=compare).json()
    second = client.post("/api/jobs", json=animate).json()
    done = wait_for(client, first["id"], timeout=120)
    assert done["state"] == "done", done
    assert "-p heeger_bergen.n_iterations=2" in done["command_line"]
    report = client.get(done["files"]["report"]["url"] + "&inline=1")
    assert report.headers["content-security-policy"].startswith("sandbox")
    assert "random_phase" in report.text and "heeger_bergen" in report.text
    ran = client.get(done["files"]["report_json"]["url"]).json()["methods"]
    assert [m["params"].get("n_iterations") for m in ran] == [None, 2]  # the job ran with them
    video = wait_for(client, second["id"], timeout=120)
    assert video["state"] == "done", video
    assert client.get(video["files"]["video"]["url"]).content[:4] == b"\x1a\x45\xdf\xa3"  # WebM (EBML)
    run = client.get(video["files"]["run"]["url"]).json()
    assert run["seed"] == 3 and run["params"]["n_iterations"] == 5


def test_the_queue_cancel_and_the_time_limit(tmp_path):
    with live_server(tmp_path, workers=1, queue_limit=1, job_timeout=1.5) as small, small.client() as c:
        long = {"exemplar": "builtin:brick", "method": "efros_leung", "size": [400, 400], "seed": 1}
        first = c.post("/api/jobs", json=long).json()
        second = c.post("/api/jobs", json=long).json()
        assert second["state"] == "queued" and second["position"] == 1
        full = c.post("/api/jobs", json=long)
        assert full.status_code == 503 and "queue is full" in full.json()["error"]
        cancelled = c.post(f"/api/jobs/{second['id']}/cancel").json()
        assert cancelled["state"] == "cancelled"
        timed_out = wait_for(c, first["id"], timeout=30)
        assert timed_out["state"] == "failed" and "time limit" in timed_out["error"]
        assert not any(p.suffix == ".part" or ".part" in p.name for p in (tmp_path / "jobs").rglob("*"))


def test_unknown_routes_answer_with_the_one_line_error_too(client):
    for path in (
        "/api/nothing",
        "/api/exemplars/..%2F..%2Fetc%2Fpasswd/preview",
        "/static/../pyproject.toml",
    ):
        response = client.get(path)
        assert response.status_code == 404 and set(response.json()) == {"error"}
    assert set(client.put("/api/jobs").json()) == {"error"}


def test_a_compare_report_names_the_users_file_not_the_servers_copy(server, client, uploaded):
    request = {"mode": "compare", "exemplar": uploaded["id"], "methods": ["random_phase"], "size": [32, 32]}
    job = wait_for(client, client.post("/api/jobs", json=request).json()["id"], timeout=120)
    assert job["state"] == "done", job
    data = client.get(job["files"]["report_json"]["url"]).json()
    assert data["exemplar_path"] == "my blocks.png" and data["command_line"] == job["command_line"]
    page = client.get(job["files"]["report"]["url"]).text
    assert str(server.folder) not in page and "my blocks.png" in page


def test_a_failed_measuring_step_leaves_the_output_with_a_warning(tmp_path):
    import asyncio
    import sys

    from texsyn.web.jobs import JobManager
    from texsyn.web.requests import DownloadFile, JobPlan
    from texsyn.web.uploads import Exemplar

    exemplar = Exemplar("builtin:brick", "builtin:brick", "builtin:brick", tmp_path / "p.png", 8, 8, 1)
    make = [sys.executable, "-c", "open('texture.png', 'wb').write(b'png')"]
    fail = [
        sys.executable,
        "-c",
        "import sys; sys.stderr.write('texsyn: error: no memory left\\n'); sys.exit(1)",
    ]
    plan = JobPlan("synth", "x", exemplar, [make, fail], "texsyn synth ...", 1, {}, optional_from=1)
    plan.files = {"image": DownloadFile("texture.png", "t.png", "image/png")}

    async def run() -> dict:
        manager = JobManager(tmp_path / "jobs", workers=1, queue_limit=1, timeout=60)
        job = manager.submit(plan)
        while job.state not in ("done", "failed", "cancelled"):
            await asyncio.sleep(0.02)
        return job.public()

    record = asyncio.run(run())
    assert record["state"] == "done" and "image" in record["files"]
    assert record["warning"] == "the output is ready, but measuring it failed: no memory left"
    plan.optional_from = None  # the same failure in a required step fails the job
    record = asyncio.run(run())
    assert record["state"] == "failed" and record["error"] == "no memory left"
