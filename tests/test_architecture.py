"""cfteach's imports keep the shape docs/architecture.md draws: no import cycles between
modules, no import from a lower layer to a higher one, a map that names every package, and
no module over 500 lines.

The layer order is read from the diagram in docs/architecture.md (tests/import_graph.py
says how), so the document and this test cannot drift apart. The graph is read with `ast`:
imports inside functions and relative imports count; imports under `if TYPE_CHECKING:` do
not count as cycles (they never run) but do count as layer violations. The checks
themselves are tested below on small synthetic packages that have, or lack, each fault.
"""

from __future__ import annotations

import importlib
import re
from pathlib import Path

import pytest

import import_graph as g

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "src" / "cfteach"
ARCHITECTURE = ROOT / "docs" / "architecture.md"


def cycle_problems(root: Path) -> list[str]:
    return [f"import cycle: {' -> '.join(cycle)}  (modules importing each other: "
            f"{', '.join(members)})" for members, cycle in g.cycles(g.import_edges(root))]


def layer_problems(root: Path, doc: Path) -> list[str]:
    ranks = g.layer_of(root.name, g.layers(doc))
    return [f"upward import: {e.source} imports {e.target} ({e.path.relative_to(root.parent)}"
            f":{e.line}); {doc.name} puts {e.target.split('.')[1]} above "
            f"{e.source.split('.')[1]}" for e in g.upward(g.import_edges(root), ranks)]


#: A module longer than this mixes jobs; split it along its seams (docs/architecture.md).
MAX_LINES = 500


def long_modules(root: Path) -> list[str]:
    """Every Python or JavaScript source file under `root` longer than MAX_LINES."""
    files = sorted([*root.rglob("*.py"), *root.rglob("*.js")])
    counts = {f: len(f.read_text(encoding="utf-8").splitlines()) for f in files}
    return [f"{f.relative_to(root.parent)}: {n} lines (more than {MAX_LINES})"
            for f, n in counts.items() if n > MAX_LINES]


def map_problems(root: Path, doc: Path) -> list[str]:
    missing, unnamed = g.unmapped(root, g.layers(doc))
    return ([f"{doc.name} names {m}, which is not in {root.name}/" for m in missing]
            + [f"{root.name}/{u} is not in {doc.name}'s diagram" for u in unnamed])


# -- cfteach itself ----------------------------------------------------------------------

def test_no_module_is_longer_than_500_lines() -> None:
    assert long_modules(PACKAGE) == []



def test_no_import_cycles() -> None:
    problems = cycle_problems(PACKAGE)
    assert not problems, "\n".join(problems)


def test_no_import_from_a_lower_layer_to_a_higher_one() -> None:
    problems = layer_problems(PACKAGE, ARCHITECTURE)
    assert not problems, "\n".join(problems)


def test_the_diagram_names_every_package_and_only_those() -> None:
    problems = map_problems(PACKAGE, ARCHITECTURE)
    assert not problems, "\n".join(problems)


def test_the_diagram_reads_as_the_documented_layer_order() -> None:
    """The parser reads what a person reads: cli on top, the jsonable utility at the bottom,
    analysis above study, and the picture-makers side by side."""
    order = g.layers(ARCHITECTURE)
    assert order[0] == ["cli"] and order[-1] == ["jsonable"]
    flat = [n for row in order for n in row]
    assert len(flat) == len(set(flat))
    assert flat.index("analysis") < flat.index("study") < flat.index("closedloop")
    assert flat.index("teaching") < flat.index("bec") < flat.index("geometry")
    assert any({"report", "render", "gym"} <= set(row) for row in order)


_NAMED = re.compile(r"`(cfteach(?:\.[a-z_][a-z0-9_]*)+)`|`([a-z_]+/[a-z_0-9/]*[a-z_0-9]+\.py)`")


def _exists(dotted: str) -> bool:
    """A module, or a name a module defines (`cfteach.parallel.Executor`)."""
    parts = dotted.split(".")
    for k in range(len(parts), 1, -1):
        try:
            mod = importlib.import_module(".".join(parts[:k]))
        except ModuleNotFoundError:
            continue
        rest = parts[k:]
        return len(rest) <= 1 and all(hasattr(mod, r) for r in rest)
    return False


def test_every_module_the_document_names_exists() -> None:
    """`cfteach.x.y` names and `pkg/module.py` paths (in src/cfteach, or from the
    repository's root) in docs/architecture.md are real."""
    text = ARCHITECTURE.read_text(encoding="utf-8")
    found = _NAMED.findall(text)
    assert found  # the pattern still matches how the document writes names
    missing = [d for d, _ in found if d and not _exists(d)]
    missing += [p for _, p in found
                if p and not ((PACKAGE / p).is_file() or (ROOT / p).is_file())]
    assert not missing, f"docs/architecture.md names what does not exist: {missing}"


# -- the checks, on synthetic packages ---------------------------------------------------

DIAGRAM = """# Architecture

```
 top/           the highest layer
                (a description can run on)
 mid/ side/     two packages side by side
 low/           the lowest package
 util.py        a module every layer may use
```
"""


def _package(tmp_path: Path, files: dict[str, str]) -> Path:
    root = tmp_path / "pkg"
    for name, body in {"__init__.py": "", **files}.items():
        path = root / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(body, encoding="utf-8")
    (tmp_path / "architecture.md").write_text(DIAGRAM, encoding="utf-8")
    return root


CLEAN = {
    "util.py": "X = 1\n",
    "low/__init__.py": "from .core import Thing\n",
    "low/core.py": "from pkg.util import X\n\nclass Thing: ...\n",
    "mid/__init__.py": "",
    "mid/a.py": "from pkg.low import Thing\nfrom . import b\n",
    "mid/b.py": "from ..low.core import Thing\n",
    "side/__init__.py": "from pkg.mid import a\n",
    "top/__init__.py": "import pkg.side\nimport pkg.mid.a\n",
}


def test_synthetic_long_module_is_named(tmp_path: Path) -> None:
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    (pkg / "short.py").write_text("x = 1\n" * MAX_LINES)
    (pkg / "long.js").write_text("let x = 1;\n" * (MAX_LINES + 1))
    assert long_modules(pkg) == [f"pkg/long.js: {MAX_LINES + 1} lines (more than {MAX_LINES})"]


def test_synthetic_clean_package_passes(tmp_path: Path) -> None:
    root = _package(tmp_path, CLEAN)
    doc = tmp_path / "architecture.md"
    assert g.layers(doc) == [["top"], ["mid", "side"], ["low"], ["util"]]
    assert cycle_problems(root) == []
    assert layer_problems(root, doc) == []
    assert map_problems(root, doc) == []
    # the relative imports resolved to the modules they name
    edges = {(e.source, e.target) for e in g.import_edges(root)}
    assert ("pkg.mid.a", "pkg.mid.b") in edges and ("pkg.mid.b", "pkg.low.core") in edges
    assert ("pkg.top", "pkg.mid.a") in edges and ("pkg.low", "pkg.low.core") in edges


def test_synthetic_cycle_through_a_function_import_is_named(tmp_path: Path) -> None:
    files = dict(CLEAN)
    files["mid/b.py"] = "def f():\n    from pkg.mid.c import g\n    return g\n"
    files["mid/c.py"] = "from .a import z\n"  # a -> b -> c -> a
    root = _package(tmp_path, files)
    (problem,) = cycle_problems(root)
    assert "pkg.mid.a -> pkg.mid.b -> pkg.mid.c -> pkg.mid.a" in problem


def test_synthetic_type_checking_import_is_no_cycle_but_is_an_upward_import(
        tmp_path: Path) -> None:
    files = dict(CLEAN)
    files["low/core.py"] = ("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n"
                            "    from pkg.mid.a import A\nclass Thing: ...\n")
    root = _package(tmp_path, files)
    assert cycle_problems(root) == []
    (problem,) = layer_problems(root, tmp_path / "architecture.md")
    assert "pkg.low.core imports pkg.mid.a" in problem and "low/core.py:3" in problem


def test_synthetic_upward_import_is_named(tmp_path: Path) -> None:
    files = dict(CLEAN)
    files["top/leaf.py"] = "T = 1\n"
    files["low/core.py"] = "class Thing:\n    def m(self):\n        from ..top.leaf import T\n"
    root = _package(tmp_path, files)
    doc = tmp_path / "architecture.md"
    (problem,) = layer_problems(root, doc)
    assert "pkg.low.core imports pkg.top.leaf" in problem and "low/core.py:3" in problem
    assert "puts top above low" in problem
    assert cycle_problems(root) == []  # the leaf imports nothing back


def test_synthetic_sideways_import_is_allowed(tmp_path: Path) -> None:
    files = dict(CLEAN)
    files["mid/b.py"] = "import pkg.side\n"  # same layer
    root = _package(tmp_path, files)
    assert layer_problems(root, tmp_path / "architecture.md") == []


def test_synthetic_map_names_missing_and_unmapped_packages(tmp_path: Path) -> None:
    files = dict(CLEAN)
    files["extra/__init__.py"] = ""
    root = _package(tmp_path, files)
    (root / "side" / "__init__.py").unlink()
    (root / "side").rmdir()
    files_top = root / "top" / "__init__.py"
    files_top.write_text("", encoding="utf-8")
    problems = map_problems(root, tmp_path / "architecture.md")
    assert problems == ["architecture.md names side, which is not in pkg/",
                        "pkg/extra is not in architecture.md's diagram"]


def test_a_document_without_a_diagram_is_named(tmp_path: Path) -> None:
    doc = tmp_path / "architecture.md"
    doc.write_text("# Architecture\n\nNo picture.\n", encoding="utf-8")
    with pytest.raises(ValueError, match="no ``` diagram block"):
        g.layers(doc)
