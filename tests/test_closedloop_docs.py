"""The examples in docs/closed-loop.md run as written, and its pictures' script runs."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from doc_examples import code_blocks, run_script

ROOT = Path(__file__).resolve().parents[1]


def test_doc_examples_run(tmp_path: Path) -> None:
    blocks = code_blocks("closed-loop.md")
    assert len(blocks) >= 2
    done = run_script("\n\n".join(blocks), tmp_path)
    lines = done.stdout.splitlines()
    assert lines[0].startswith("demonstration lesson")
    assert lines[1].startswith("test diagnostic")
    assert lines[2] == "feedback"
    assert lines[3] == "2"  # the replayed session holds the two observed items


def test_pictures_script_draws_the_beliefs(tmp_path: Path) -> None:
    done = subprocess.run([sys.executable, str(ROOT / "scripts" / "closed-loop-figures.py"),
                           str(tmp_path)], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    assert sorted(p.name for p in tmp_path.glob("*.png")) == ["closed-loop-belief.png"]
    assert (tmp_path / "closed-loop-belief.png").stat().st_size > 20000
    # the docs show exactly the picture the script draws (regenerated, never stale)
    shown = (ROOT / "docs" / "closed-loop.md").read_text() + (ROOT / "README.md").read_text()
    assert "images/closed-loop-belief.png" in shown
