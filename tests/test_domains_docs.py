"""The Python examples in docs/domains.md run."""

from __future__ import annotations

import pytest

from doc_examples import DOCS, code_blocks

BLOCKS = code_blocks("domains.md")


def test_docs_have_examples() -> None:
    assert len(BLOCKS) >= 2


@pytest.mark.parametrize("i", range(len(BLOCKS)))
def test_docs_example_runs(i: int, capsys: pytest.CaptureFixture[str]) -> None:
    exec(compile(BLOCKS[i], f"{DOCS / 'domains.md'}:block{i}", "exec"), {})
    out = capsys.readouterr().out
    code = BLOCKS[i]
    if "parse_envs" in code:  # working on some environments
        assert out.splitlines() == ["[0, 5, 16, 32, 48]", "[0, 16, 32, 48]", "True"]
    elif "state_to_json" in code:
        assert "191" in out and "'station': True" in out
    elif "act(\"wait\")" in code:  # declared actions: exit ends at the start, the dock
        assert out.splitlines() == [
            "[('wait', 'w', 'stay'), ('quit', 'q', 'exit')]",
            "(1, 1, 1, 1, 0) [0.0, 0.0, 0.0] True",
            "(3, 1, 3, 1, 1) [0.0, 1.0, 1.0] False",
            "[0.0, 0.0, 1.0]",
            "(array([1., 0., 1.]), True)"]
    elif "best_tied_trajectories" in code:
        assert "(8, 2, 553, 6) True" in out and "['right', 'right']" in out
    else:  # best_tied_mu on the bounded pairs: skateboard instance 1 goes right twice
        assert "(8, 553, 3) [0 0 2]" in out
