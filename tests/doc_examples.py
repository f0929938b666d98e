"""Shared by the tests that run the examples of docs/*.md, so every page is checked alike."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parents[1] / "docs"


def code_blocks(page: str, lang: str = "python") -> list[str]:
    """The fenced `lang` code blocks of docs/<page>, in order."""
    text = (DOCS / page).read_text(encoding="utf-8")
    return re.findall(rf"```{lang}\n(.*?)```", text, flags=re.S)


def run_script(code: str, tmp_path: Path, *, name: str = "example.py",
               timeout: float = 300) -> subprocess.CompletedProcess[str]:
    """Run `code` as a fresh Python process (as a reader pasting it would) and assert it
    exits cleanly; returns the finished process for checks on its output."""
    script = tmp_path / name
    script.write_text(code, encoding="utf-8")
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                          timeout=timeout)
    assert done.returncode == 0, done.stderr
    return done
