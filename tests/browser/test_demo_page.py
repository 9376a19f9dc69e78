"""A real headless Chromium against a real server: the demo page speaks, the view connects.

Screenshots are kept in ``test-artifacts/`` (and copied to ``docs/img/`` when
``BEARINGS_UPDATE_SCREENSHOTS=1``).
"""

from __future__ import annotations

import os
import shutil
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from app.main import create_app
from tests.helpers import free_port, make_settings, serving

CHROMIUM = "/usr/bin/chromium"
ARTIFACTS = Path("test-artifacts")
ARGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
]

pytestmark = [
    pytest.mark.browser,
    pytest.mark.skipif(
        not Path(CHROMIUM).exists() and not os.environ.get("CI"),
        reason="Debian chromium is not installed (apt-get install chromium); required in CI",
    ),
]


@pytest.fixture(scope="module")
def live_app() -> Iterator[tuple[str, object]]:
    port, viser_port = free_port(), free_port()
    app = create_app(make_settings(viser=True, viser_port=viser_port, port=port))
    with serving(app, port) as url:
        yield f"http://{url}", app


def keep(page, name: str) -> None:
    ARTIFACTS.mkdir(exist_ok=True)
    path = ARTIFACTS / name
    page.screenshot(path=str(path))
    if os.environ.get("BEARINGS_UPDATE_SCREENSHOTS"):
        Path("docs/img").mkdir(parents=True, exist_ok=True)
        shutil.copy(path, Path("docs/img") / name)


def test_demo_page_walks_speaks_and_shows_the_view(live_app) -> None:
    from playwright.sync_api import sync_playwright

    url, app = live_app
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=ARGS, headless=True)
        try:
            page = browser.new_page(viewport={"width": 1400, "height": 900})
            page.add_init_script(
                # Record what the page asks the speech engine to say.
                "window.__spoken = []; if (window.speechSynthesis) {"
                " window.speechSynthesis.speak = (u) => window.__spoken.push(u.text); }"
            )
            page.goto(url + "/")
            page.wait_for_function("document.querySelectorAll('#map option').length > 0")
            live = page.locator("#feedback")
            assert live.get_attribute("aria-live") == "polite"
            page.keyboard.press("Tab")  # keyboard-operable: the first control takes focus
            page.locator("#start").focus()
            page.keyboard.press("Enter")
            page.wait_for_function(
                "document.querySelector('#feedback').textContent.includes('where you are')"
                " || document.querySelector('#feedback').textContent.includes('You are in')",
                timeout=30_000,
            )
            page.wait_for_function(
                "document.querySelector('#status').textContent.includes('located')", timeout=60_000
            )
            page.locator("#whereami").click()
            page.wait_for_function(
                "document.querySelector('#feedback').textContent.includes('You are in Office')",
                timeout=30_000,
            )
            spoken = page.evaluate("window.__spoken")
            assert any("You are in Office" in s for s in spoken)
            keep(page, "demo_page.png")

            viser_port = app.state.view.port
            view = browser.new_page(viewport={"width": 1200, "height": 800})
            view.goto(f"http://127.0.0.1:{viser_port}/")
            deadline = time.time() + 30
            while not app.state.view.server.get_clients() and time.time() < deadline:
                time.sleep(0.2)
            assert app.state.view.server.get_clients(), "the viser page did not connect"
            view.wait_for_selector("canvas", timeout=30_000)
            time.sleep(3.0)  # let the scene arrive and render
            keep(view, "viser_view.png")
        finally:
            browser.close()
