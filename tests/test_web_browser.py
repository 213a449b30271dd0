"""The page of ``texsyn serve`` in a real browser (issue 21): Playwright driving the Debian
``chromium`` package, which ``.ci/run`` installs so that these run in CI."""

from __future__ import annotations

import time

import numpy as np
import pytest

from browser_utils import CHROMIUM_FLAGS, find_chromium

pytest.importorskip("fastapi")
playwright = pytest.importorskip("playwright.sync_api")

from texsyn.cli import main  # noqa: E402
from texsyn.io import write_image  # noqa: E402
from web_utils import live_server  # noqa: E402

CHROMIUM = find_chromium()
pytestmark = pytest.mark.skipif(
    CHROMIUM is None, reason="Debian's chromium is not installed (.ci/run installs it)"
)


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    with live_server(tmp_path_factory.mktemp("serve"), workers=2) as live:
        yield live


@pytest.fixture(scope="module")
def browser():
    with playwright.sync_playwright() as p:
        chromium = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_FLAGS)
        yield chromium
        chromium.close()


@pytest.fixture
def page(browser, server):
    # bypass_csp: the page's policy forbids the string evaluation Playwright's waits use
    context = browser.new_context(
        accept_downloads=True, bypass_csp=True, viewport={"width": 1300, "height": 1000}
    )
    tab = context.new_page()
    tab.goto(server.page)
    tab.wait_for_selector("#builtins button")
    yield tab
    context.close()


@pytest.fixture(scope="module")
def exemplar_png(tmp_path_factory):
    rng = np.random.default_rng(5)
    image = np.kron(rng.random((10, 10, 3)), np.ones((5, 5, 1)))
    path = tmp_path_factory.mktemp("ex") / "tiles.png"
    write_image(path, image)
    return path


def upload(page, path) -> None:
    page.set_input_files("#file", str(path))
    page.wait_for_function(
        "name => document.getElementById('exemplar-name').textContent.startsWith(name)", arg=path.name
    )


def run_and_wait(page, timeout=60_000) -> None:
    page.click("#run")
    page.wait_for_selector("#status[data-state=done]", timeout=timeout)


def test_upload_run_quilting_see_the_output_and_map_and_download_the_same_bytes(page, exemplar_png, tmp_path):
    upload(page, exemplar_png)
    page.fill("#width", "80")
    page.fill("#height", "64")
    page.fill("#seed", "4242")
    page.select_option("#method", "quilting")
    page.fill("#p-quilting-patch_size", "20")
    run_and_wait(page)
    for image in ("#out-image", "#out-map"):
        page.wait_for_function(f"document.querySelector('{image}').naturalWidth === 80")
    assert page.is_visible("#fig-map")
    assert page.locator("#metrics tbody tr").count() >= 5
    line = page.text_content("#command-line")
    assert line.startswith("texsyn synth tiles.png -m quilting --size 80x64 --seed 4242 -p patch_size=20")
    with page.expect_download() as info:
        page.click("#downloads a[data-key=image]")
    download = info.value
    assert download.suggested_filename == "texsyn-quilting-4242.png"
    got = tmp_path / "page.png"
    download.save_as(got)
    cli = [
        "synth",
        str(exemplar_png),
        "-m",
        "quilting",
        "--size",
        "80x64",
        "--seed",
        "4242",
        "-p",
        "patch_size=20",
    ]
    assert main([*cli, "-q", "-o", str(tmp_path / "cli.png")]) == 0
    assert got.read_bytes() == (tmp_path / "cli.png").read_bytes()


def test_a_bad_file_and_a_30_mb_upload_get_clear_messages_and_the_server_keeps_serving(page, tmp_path):
    bad = tmp_path / "notes.png"
    bad.write_bytes(b"these are notes, not a picture")
    page.set_input_files("#file", str(bad))
    page.wait_for_selector("#error:not([hidden])")
    assert "allowed types: PNG, JPEG, TIFF, WebP, BMP" in page.text_content("#error")
    big = tmp_path / "huge.png"
    big.write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(30_000_000))
    page.set_input_files("#file", str(big))
    page.wait_for_function("document.getElementById('error').textContent.includes('20 MB upload limit')")
    # the page checks the size before sending; the server refuses it too (test_web_api)
    page.click("#builtins button[data-id='builtin:grass']")
    page.fill("#width", "48")
    page.fill("#height", "48")
    page.select_option("#method", "random_phase")
    page.uncheck("#measure")
    run_and_wait(page)
    assert page.is_hidden("#error")


def test_a_bad_parameter_shows_the_command_lines_message(page):
    page.fill("#p-quilting-patch_size", "-3")
    page.click("#run")
    page.wait_for_selector("#error:not([hidden])")
    assert "parameter 'patch_size' of method 'quilting' must be in" in page.text_content("#error")


def test_cancel_stops_a_long_efros_leung_job_within_a_second(page):
    page.select_option("#method", "efros_leung")
    page.fill("#width", "512")
    page.fill("#height", "512")
    page.click("#run")
    page.wait_for_function(
        "/pixels \\d+\\/\\d+/.test(document.getElementById('status-text').textContent)", timeout=30_000
    )
    start = time.monotonic()
    page.click("#cancel")
    page.wait_for_selector("#status[data-state=cancelled]", timeout=5_000)
    # 'cancelled' is shown once the job's process has ended (texsyn.web.jobs)
    assert time.monotonic() - start < 1.0


def test_two_jobs_at_once_from_two_pages_both_finish(browser, server):
    tabs = []
    for method in ("quilting", "heeger_bergen"):
        context = browser.new_context(bypass_csp=True)
        tab = context.new_page()
        tab.goto(server.page)
        tab.wait_for_selector("#builtins button")
        tab.fill("#width", "64")
        tab.fill("#height", "64")
        tab.select_option("#method", method)
        tab.uncheck("#measure")
        tabs.append(tab)
    for tab in tabs:
        tab.click("#run")
    commands = []
    for tab in tabs:
        tab.wait_for_selector("#status[data-state=done]", timeout=60_000)
        tab.wait_for_function("document.getElementById('out-image').naturalWidth === 64")
        assert tab.text_content("#status-text").startswith("done in")
        assert tab.is_hidden("#error")
        commands.append(tab.text_content("#command-line"))
        tab.context.close()
    assert "-m quilting" in commands[0] and "-m heeger_bergen" in commands[1]


def test_compare_mode_shows_the_reports_table_and_pictures(page):
    page.click("#modes button[data-mode=compare]")
    page.fill("#width", "64")
    page.fill("#height", "64")
    run_and_wait(page, timeout=120_000)
    frame = page.frame_locator("#report")
    assert frame.locator("table").first.is_visible()
    assert frame.locator("img").count() >= 4
    assert page.text_content("#command-line").startswith("texsyn compare builtin:brick -m heeger_bergen")


def test_animate_mode_plays_the_video_in_the_page(page):
    page.click("#modes button[data-mode=animate]")
    page.fill("#frames", "6")
    page.fill("#width", "48")
    page.fill("#height", "48")
    run_and_wait(page, timeout=120_000)
    page.wait_for_function("document.getElementById('out-video').readyState >= 2", timeout=20_000)
    assert page.evaluate("document.getElementById('out-video').videoWidth") == 48
