"""The examples in docs/simulate.md run as written."""

from __future__ import annotations

from pathlib import Path

from doc_examples import code_blocks, run_script


def test_doc_examples_run(tmp_path: Path) -> None:
    blocks = code_blocks("simulate.md")
    assert len(blocks) >= 2
    done = run_script("\n".join(blocks), tmp_path)
    untaught, taught = (float(x) for x in done.stdout.split()[:2])
    assert 0 <= untaught <= 1 and 0 <= taught <= 1
