"""The project's own files stand on their own: a licence, a citation, an SPDX licence in
pyproject (no setuptools deprecation warning), and docs that cite the paper, not a spec
that does not ship."""

from __future__ import annotations

import importlib.metadata
import re
import tomllib
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]


def test_pyproject_uses_an_spdx_licence_and_ships_the_licence_file() -> None:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert project["license"] == "MIT"  # a string: the table form is deprecated
    assert project["license-files"] == ["LICENSE"]
    assert "MIT License" in (ROOT / "LICENSE").read_text()
    assert importlib.metadata.metadata("cfteach")["License-Expression"] == "MIT"


def test_citation_cites_cfteach_and_the_paper() -> None:
    cff = yaml.safe_load((ROOT / "CITATION.cff").read_text())
    assert cff["cff-version"] == "1.2.0" and cff["title"].startswith("cfteach")
    assert cff["version"] == importlib.metadata.version("cfteach")
    paper = cff["preferred-citation"]
    assert paper["title"] == ("Reasoning about Counterfactuals to Improve Human Inverse "
                              "Reinforcement Learning")
    assert [a["family-names"] for a in paper["authors"]] == ["Lee", "Admoni", "Simmons"]
    assert paper["year"] == 2022


def test_docs_do_not_cite_a_spec_that_does_not_ship() -> None:
    pages = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
    hits = [f"{p.name}:{i}" for p in pages
            for i, line in enumerate(p.read_text().splitlines(), 1)
            if re.search(r"spec\s*§|reference-spec|reference spec|\.\./shared", line)]
    assert hits == []
