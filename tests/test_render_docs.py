"""The Python examples in docs/rendering.md run as written."""

from __future__ import annotations

import re

import pytest

from doc_examples import DOCS, code_blocks

DOC = DOCS / "rendering.md"
BLOCKS = code_blocks("rendering.md")


def test_the_doc_has_examples():
    assert len(BLOCKS) >= 4


@pytest.mark.parametrize("index", range(len(BLOCKS)))
def test_doc_example_runs(index, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    exec(compile(BLOCKS[index], f"{DOC.name}[{index}]", "exec"), {"__name__": "__doc__"})
    written = list(tmp_path.iterdir())
    for path in written:
        assert path.stat().st_size > 0, path


def test_first_example_prints_what_the_doc_shows(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    exec(compile(BLOCKS[0], "rendering.md[0]", "exec"), {})
    shown = re.search(r"prints\n\n```\n(.*?)```", DOC.read_text(encoding="utf-8"), re.S)
    assert shown is not None
    assert capsys.readouterr().out == shown.group(1)
