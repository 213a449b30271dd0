"""Take the screenshot of ``texsyn serve`` that README.md and docs/web.md show.

Starts a server on a free loopback port, opens the page in the system's Chromium (Debian's
``chromium`` package) through Playwright, runs a comparison of three methods on the built-in
brick exemplar and saves the finished page to ``docs/images/web-compare.png``::

    python benchmarks/web_screenshot.py [--out docs/images/web-compare.png]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from playwright.sync_api import sync_playwright

from browser_utils import CHROMIUM_FLAGS, find_chromium
from web_utils import live_server

ROOT = Path(__file__).resolve().parents[1]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "images" / "web-compare.png")
    parser.add_argument("--methods", default="quilting,heeger_bergen,random_phase,efros_leung")
    args = parser.parse_args()
    chromium = find_chromium()
    if chromium is None:
        sys.exit("web_screenshot: Debian's chromium is needed (apt-get install chromium)")
    with tempfile.TemporaryDirectory() as folder, live_server(Path(folder)) as server, sync_playwright() as p:
        browser = p.chromium.launch(executable_path=chromium, args=CHROMIUM_FLAGS)
        page = browser.new_page(viewport={"width": 1400, "height": 1050}, bypass_csp=True)
        page.goto(server.page)
        page.wait_for_selector("#builtins button")
        page.click("#modes button[data-mode=compare]")
        for box in page.locator("#compare-methods input").all():
            box.set_checked(box.get_attribute("value") in args.methods.split(","))
        page.fill("#width", "192")
        page.fill("#height", "192")
        page.click("#run")
        page.wait_for_selector("#status[data-state=done]", timeout=300_000)
        page.wait_for_timeout(1000)
        page.evaluate("window.scrollTo(0, 0)")
        args.out.parent.mkdir(parents=True, exist_ok=True)
        page.screenshot(path=str(args.out))
        browser.close()
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
