"""The examples in docs/parallel.md run as written."""

from __future__ import annotations

from pathlib import Path

from doc_examples import code_blocks, run_script


def test_doc_examples_run(tmp_path: Path) -> None:
    blocks = code_blocks("parallel.md")
    assert len(blocks) >= 2
    for i, block in enumerate(blocks):  # each on its own, as a reader pastes one
        run_script(block, tmp_path, name=f"example{i}.py", timeout=120)
