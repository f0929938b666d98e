"""The import graph of a package, read with `ast`, and the layer order of docs/architecture.md.

Used by tests/test_architecture.py, which checks cfteach itself and, on tiny synthetic
packages, that the checks catch what they should. Nothing is imported: every `.py` file is
parsed, so a broken module cannot hide an edge.

What counts as an import: every `import` / `from ... import` statement anywhere in a file
(module level, inside functions and classes, relative or absolute), except those under
`if TYPE_CHECKING:`, which never run and so cannot form a runtime cycle (the layer check
still counts them: a type named from a higher layer is still a dependency on it). The
implicit import of a parent package's `__init__` is not an edge (else every package whose
`__init__` re-exports its modules would be a cycle).
"""

from __future__ import annotations

import ast
import re
from collections import deque
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components


@dataclass(frozen=True)
class Edge:
    """`source` imports `target` (both dotted module names) at `path:line`."""

    source: str
    target: str
    path: Path
    line: int
    type_only: bool


def module_files(root: Path) -> dict[str, Path]:
    """Dotted module name -> file, for the package whose directory is `root`."""
    out: dict[str, Path] = {}
    for path in sorted(root.rglob("*.py")):
        parts = list(path.relative_to(root.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        out[".".join(parts)] = path
    return out


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def _imports(tree: ast.AST) -> list[tuple[ast.Import | ast.ImportFrom, bool]]:
    """Every import statement in `tree`, with whether it sits under `if TYPE_CHECKING:`."""
    found: list[tuple[ast.Import | ast.ImportFrom, bool]] = []

    def walk(node: ast.AST, type_only: bool) -> None:
        if isinstance(node, ast.If) and _is_type_checking(node.test):
            for child in node.body:
                walk(child, True)
            for child in node.orelse:
                walk(child, type_only)
            return
        if isinstance(node, ast.Import | ast.ImportFrom):
            found.append((node, type_only))
        for child in ast.iter_child_nodes(node):
            walk(child, type_only)

    walk(tree, False)
    return found


def _base(module: str, is_package: bool, node: ast.ImportFrom) -> str:
    """The absolute module a `from X import ...` names (resolving leading dots)."""
    if not node.level:
        return node.module or ""
    parts = module.split(".")
    if not is_package:
        parts = parts[:-1]
    parts = parts[: len(parts) - (node.level - 1)]
    return ".".join(parts + ([node.module] if node.module else []))


def import_edges(root: Path) -> list[Edge]:
    """Every import inside the package at `root` that names one of its own modules."""
    files = module_files(root)
    edges: list[Edge] = []
    for module, path in files.items():
        is_package = path.name == "__init__.py"
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        for node, type_only in _imports(tree):
            targets: list[str] = []
            if isinstance(node, ast.Import):
                for alias in node.names:
                    name = alias.name
                    while name and name not in files:  # `import a.b.c` needs a.b.c
                        name = name.rpartition(".")[0]
                    targets.append(name)
            else:
                base = _base(module, is_package, node)
                for alias in node.names:
                    sub = f"{base}.{alias.name}"
                    targets.append(sub if sub in files else base)
            for target in targets:
                if target in files and target != module:
                    edges.append(Edge(module, target, path, node.lineno, type_only))
    return list(dict.fromkeys(edges))  # `from x import a, b` is one import of x


def cycles(edges: list[Edge]) -> list[tuple[list[str], list[str]]]:
    """Per group of modules that import each other (a strongly connected component of more
    than one module): its members, and one shortest cycle through the first of them (a
    list of modules, first repeated last)."""
    runtime = [e for e in edges if not e.type_only]
    names = sorted({e.source for e in runtime} | {e.target for e in runtime})
    index = {n: i for i, n in enumerate(names)}
    if not names:
        return []
    rows = [index[e.source] for e in runtime]
    cols = [index[e.target] for e in runtime]
    graph = csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(len(names), len(names)))
    _, labels = connected_components(graph, directed=True, connection="strong")
    out = []
    for label in np.unique(labels):
        members = {names[i] for i in np.flatnonzero(labels == label)}
        if len(members) > 1:
            out.append((sorted(members), _one_cycle(sorted(members), runtime)))
    return sorted(out)


def _one_cycle(members: list[str], edges: list[Edge]) -> list[str]:
    """The shortest cycle through the first member, inside its strongly connected group."""
    inside = set(members)
    succ: dict[str, list[str]] = {}
    for e in edges:
        if e.source in inside and e.target in inside:
            succ.setdefault(e.source, []).append(e.target)
    start = members[0]
    came_from: dict[str, str] = {}
    queue = deque([start])
    while queue:
        node = queue.popleft()
        for nxt in sorted(set(succ.get(node, []))):
            if nxt == start:
                path = [node]
                while path[-1] != start:
                    path.append(came_from[path[-1]])
                return [start, *reversed(path[:-1]), start]
            if nxt not in came_from:
                came_from[nxt] = node
                queue.append(nxt)
    raise AssertionError(f"no cycle through {start}")  # impossible in a strong component


# -- the layer diagram ---------------------------------------------------------------------

_ENTRY = re.compile(r"[a-z_][a-z0-9_]*(?:/|\.py)")


def layers(architecture_md: Path) -> list[list[str]]:
    """The layers of the first code block in `architecture_md`, top (imports most) first.

    A layer is a diagram line that starts with one space and then one or more entries
    (`name/` for a subpackage, `name.py` for a module), separated by spaces; the rest of the
    line and the indented lines below it are its description."""
    text = architecture_md.read_text(encoding="utf-8")
    block = re.search(r"^```\n(.*?)^```", text, flags=re.S | re.M)
    if block is None:
        raise ValueError(f"{architecture_md}: no ``` diagram block")
    out: list[list[str]] = []
    for line in block.group(1).splitlines():
        if not line.startswith(" ") or line.startswith("  "):
            continue
        entries = []
        for token in line.split():
            if not _ENTRY.fullmatch(token):
                break
            entries.append(token.removesuffix("/").removesuffix(".py"))
        if entries:
            out.append(entries)
    if not out:
        raise ValueError(f"{architecture_md}: the diagram names no layer")
    return out


def layer_of(package: str, order: list[list[str]]) -> dict[str, int]:
    """`package.entry` -> rank (0 = lowest layer) for every entry of the diagram."""
    return {f"{package}.{name}": len(order) - 1 - i
            for i, row in enumerate(order) for name in row}


def _top(module: str, ranks: dict[str, int]) -> str | None:
    parts = module.split(".")
    return ".".join(parts[:2]) if len(parts) > 1 and ".".join(parts[:2]) in ranks else None


def upward(edges: list[Edge], ranks: dict[str, int]) -> list[Edge]:
    """Imports from a layer to a higher one (type-only imports included)."""
    out = []
    for e in edges:
        a, b = _top(e.source, ranks), _top(e.target, ranks)
        if a and b and ranks[b] > ranks[a]:
            out.append(e)
    return out


def unmapped(root: Path, order: list[list[str]]) -> tuple[list[str], list[str]]:
    """(entries of the diagram missing from the tree, subpackages/modules missing from it)."""
    named = {n for row in order for n in row}
    present = {p.name for p in root.iterdir() if (p / "__init__.py").is_file()} | {
        p.stem for p in root.glob("*.py") if p.name != "__init__.py"}
    return sorted(named - present), sorted(present - named)
