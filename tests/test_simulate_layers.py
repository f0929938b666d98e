"""The simulate package's modules stand on each other in one direction: the closed-loop
simulation does not import the sweep that drives it (no import cycle)."""

from __future__ import annotations

import ast
from pathlib import Path

import cfteach.simulate


def _imports(module: str) -> set[str]:
    path = Path(cfteach.simulate.__file__).parent / f"{module}.py"
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module:
            out.add(node.module)
        elif isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
    return out


def test_closed_loop_does_not_import_the_sweep():
    assert "cfteach.simulate.closed_loop" in _imports("sweep")
    assert "cfteach.simulate.sweep" not in _imports("closed_loop")
    assert "cfteach.simulate.sweep" not in _imports("domain_refs")


def test_the_sweep_still_offers_the_domain_references():
    from cfteach.simulate import domain_refs, sweep

    assert sweep.load_domain is domain_refs.load_domain
    assert sweep.parse_domain("random:4x3:f2:n5:s1") == ("random", 4, 3, 2, 5, 1)
    assert domain_refs.domain_label(("random", 4, 3, 2, 5, 1)) == "random-4x3-f2-n5-s1"
