"""The examples in docs/parallel.md run as written."""

from __future__ import annotations

from pathlib import Path

from doc_examples import code_blocks, run_script


def test_doc_examples_run(tmp_path: Path) -> None:
    blocks = code_blocks("parallel.md")
    assert len(blocks) >= 2
    run_script("\n".join(blocks), tmp_path, timeout=120)
