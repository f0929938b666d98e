"""Open the report in headless Chromium (Debian's, never a downloaded one) and check that the
curricula and every picture are actually visible."""

from __future__ import annotations

import os
import shutil

import pytest

from cfteach.report import build_report, write_results

pytestmark = pytest.mark.browser

CHROMIUM = os.environ.get("CFTEACH_CHROMIUM", "/usr/bin/chromium")
ARGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
]


@pytest.fixture(scope="module")
def page(tmp_path_factory):
    if not shutil.which(CHROMIUM) and not os.path.exists(CHROMIUM):
        pytest.fail(f"Chromium not found at {CHROMIUM} (apt-get install chromium)")
    from playwright.sync_api import sync_playwright

    from test_report import make_results

    out = tmp_path_factory.mktemp("report-browser")
    results = make_results()
    write_results(out, results)
    index = build_report(out, results, sphere_resolution=24, progress=False)
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        pg = browser.new_page(viewport={"width": 1280, "height": 900})
        pg.goto(index.resolve().as_uri())
        pg.wait_for_load_state("load")
        yield pg
        browser.close()


def test_four_curricula_side_by_side_are_visible(page):
    columns = page.locator(".column")
    assert columns.count() == 4
    boxes = [columns.nth(i).bounding_box() for i in range(4)]
    assert all(b is not None and b["width"] > 150 for b in boxes)
    tops = {round(b["y"]) for b in boxes}
    assert len(tops) == 1  # one row: side by side
    assert [b["x"] for b in boxes] == sorted(b["x"] for b in boxes)
    names = [columns.nth(i).locator("h4").inner_text() for i in range(4)]
    assert names == ["baseline", "feature_only", "counterfactual_only", "proposed"]
    for i in range(4):
        assert columns.nth(i).locator(".demo").count() == 2


def test_every_image_loads_and_has_a_size(page):
    images = page.locator("img")
    n = images.count()
    assert n == 4 * 3 + 1 + 3 + 3
    broken = page.evaluate(
        "() => Array.from(document.images)"
        ".filter(i => !i.complete || i.naturalWidth === 0).map(i => i.src)"
    )
    assert broken == []
    for i in range(n):
        img = images.nth(i)
        img.scroll_into_view_if_needed()
        assert img.is_visible()
        box = img.bounding_box()
        assert box is not None and box["width"] > 50 and box["height"] > 50


def test_summary_and_tests_are_shown(page):
    assert page.locator("table.summary-curricula tbody tr").count() == 1  # one per domain
    cells = page.locator("table.summary-curricula td[data-cell]")
    assert cells.count() == 4 and all(cells.nth(i).is_visible() for i in range(4))
    assert page.locator("table.summary-tests tbody tr").count() == 1
    for level in ("low", "medium", "high"):
        block = page.locator(f'.level[data-level="{level}"]')
        assert block.is_visible()
        assert "overlap" in block.inner_text()
