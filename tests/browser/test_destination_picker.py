"""The demo page's destination picker in a real headless Chromium against a real server."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from app.main import create_app
from tests.browser.test_demo_page import ARGS, CHROMIUM, pytestmark  # noqa: F401
from tests.helpers import free_port, make_settings, serving


@pytest.fixture(scope="module")
def page_url() -> Iterator[str]:
    port = free_port()
    with serving(create_app(make_settings(port=port)), port) as url:
        yield f"http://{url}"


def test_picking_a_destination_guides_and_speaks(page_url: str) -> None:
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=ARGS, headless=True)
        try:
            page = browser.new_page(viewport={"width": 1400, "height": 900})
            page.add_init_script(
                "window.__spoken = []; if (window.speechSynthesis) {"
                " window.speechSynthesis.speak = (u) => window.__spoken.push(u.text); }"
            )
            page.goto(page_url + "/")
            page.wait_for_function(
                "document.querySelectorAll('#destination option').length > 3", timeout=30_000
            )
            picker = page.get_by_label("Guide me to")  # labelled for screen readers
            labels = page.locator("#destination optgroup").evaluate_all(
                "(gs) => gs.map((g) => g.label)"
            )
            assert labels == ["Places", "Nearest of a kind", "Rooms"]
            picker.select_option(label="main entrance")
            page.locator("#start").click()
            page.wait_for_function(
                "document.querySelector('#guidance').textContent.includes('main entrance')",
                timeout=60_000,
            )
            page.wait_for_function(
                "window.__spoken.some((s) => s.includes('Main entrance: go to')"
                " || s.includes('arrived at main entrance'))",
                timeout=60_000,
            )
            # Choosing "nowhere" stops the guidance.
            picker.select_option(value="")
            page.wait_for_function(
                "document.querySelector('#guidance').textContent === ''", timeout=10_000
            )
        finally:
            browser.close()
