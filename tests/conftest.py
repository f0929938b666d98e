"""Test-suite wiring shared by every test file.

Markers (registered in pyproject.toml) select the tiers of `scripts/test`: `--quick` runs
`not browser and not postgres and not slow`. So that a browser test can never slip into the
quick tier unmarked, every test in a `*_browser.py` file, and every test that asks for the
`browser` fixture (a launched Chromium), is marked `browser` here.
"""

from __future__ import annotations

import pytest

BROWSER_FIXTURES = frozenset({"browser"})


@pytest.hookimpl(tryfirst=True)  # before `-m` deselects by marker
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    for item in items:
        browser_file = item.path.name.endswith("_browser.py")
        uses_browser = BROWSER_FIXTURES & set(getattr(item, "fixturenames", ()))
        if (browser_file or uses_browser) and item.get_closest_marker("browser") is None:
            item.add_marker(pytest.mark.browser)
