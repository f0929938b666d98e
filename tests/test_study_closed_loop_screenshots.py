"""`cfteach study screenshots` on a closed-loop study: one picture per kind of item (its own
module: the screenshots start Playwright themselves, which cannot run inside another
module's open Playwright session)."""

from __future__ import annotations

from pathlib import Path

import pytest

from cfteach.study.build import init_study, preview_sources

pytestmark = [pytest.mark.browser, pytest.mark.slow]


@pytest.fixture(scope="module")
def cl_only_study(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("cl_shots")
    init_study(out, preview_sources(["skateboard"]), demo_step_ms=30,
               conditions=["closed_loop"], teacher={"n_particles": 300, "max_items": 9})
    return out


def test_screenshots_show_closed_loop_items(cl_only_study: Path, tmp_path: Path) -> None:
    """`cfteach study screenshots` takes one picture per kind of closed-loop item."""
    from PIL import Image

    from cfteach.study.screenshots import take_screenshots

    saved = take_screenshots(cl_only_study, tmp_path, kinds=("closed_loop",))
    names = sorted(p.name for p in saved)
    assert names == ["study-closed-loop-demonstration.png", "study-closed-loop-feedback.png",
                     "study-closed-loop-test.png"]
    for p in saved:
        assert Image.open(p).size[0] == 1100
