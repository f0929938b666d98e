"""The README's table of the report's numbers (written by scripts/docs_images.py together
with the screenshots) matches a fresh run of the current code."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from cfteach.teaching import teach

README = Path(__file__).resolve().parents[1] / "README.md"
CELL = re.compile(r"(\d+) demos, ([\d.e+-]+) sr")


def readme_numbers() -> dict[tuple[str, str], tuple[int, float]]:
    text = README.read_text()
    m = re.search(r"<!-- report-numbers[^\n]*-->\n(.*?)<!-- /report-numbers -->", text, re.S)
    assert m, "README.md lost its report-numbers block"
    rows = [r.strip().strip("|").split("|") for r in m.group(1).strip().splitlines()]
    header = [c.strip() for c in rows[0]][1:]
    out = {}
    for row in rows[2:]:
        domain, *cells = (c.strip() for c in row)
        for cond, cell in zip(header, cells, strict=True):
            n, area = CELL.fullmatch(cell).groups()
            out[(domain, cond)] = (int(n), float(area))
    return out


def test_readme_lists_every_domain_and_condition() -> None:
    assert len(readme_numbers()) == 12


@pytest.mark.slow
@pytest.mark.parametrize("domain", ["delivery", "tiles", "skateboard"])
def test_readme_numbers_match_a_fresh_run(domain: str) -> None:
    numbers = readme_numbers()
    for (dom, cond), (n, area) in numbers.items():
        if dom != domain:
            continue
        cur = teach(domain, cond, profile="default", seed=0)
        assert len(cur) == n, (dom, cond)
        assert float(f"{cur.final_belief.area():.4g}") == pytest.approx(area, rel=1e-9), \
            (dom, cond)
