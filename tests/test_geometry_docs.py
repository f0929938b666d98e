"""The python examples in docs/geometry.md run."""

from __future__ import annotations

from doc_examples import DOCS, code_blocks


def test_doc_examples_run() -> None:
    blocks = code_blocks("geometry.md")
    assert len(blocks) >= 3
    for block in blocks:
        exec(compile(block, str(DOCS / "geometry.md"), "exec"), {})
