"""Noisy (Boltzmann) answers. The deterministic learner planning is cfteach.mdp's, checked
against brute force in tests/test_mdp_finishing.py."""

from __future__ import annotations

import numpy as np
import pytest

from cfteach.simulate.planning import boltzmann_rollouts


def test_boltzmann_cold_is_greedy_hot_is_uniform() -> None:
    rng = np.random.default_rng(0)
    nxt = np.array([[1, 1, 1], [1, 1, 1]])  # one decision, then the sink
    feats = np.zeros((2, 3, 3))
    feats[0, np.arange(3), np.arange(3)] = 1.0  # action a fires feature a
    q = np.array([[[0.0, 1.0, 0.5], [0.0, 0.0, 0.0]]]).repeat(4000, axis=0)
    starts = np.zeros((4000, 1), dtype=int)
    mu, fin, _ = boltzmann_rollouts(nxt, feats, q, starts, 1e-3, rng, max_steps=5)
    assert fin.all() and (mu[:, 0, 1] == 1).all()
    mu, _, _ = boltzmann_rollouts(nxt, feats, q, starts, 1.0, rng, max_steps=5)
    freq = mu[:, 0].mean(axis=0)
    expected = np.exp([0.0, 1.0, 0.5]) / np.exp([0.0, 1.0, 0.5]).sum()
    np.testing.assert_allclose(freq, expected, atol=0.03)
    with pytest.raises(ValueError, match="temperature must be positive"):
        boltzmann_rollouts(nxt, feats, q, starts, 0.0, rng, max_steps=5)


def test_planning_example_in_docs_prints_what_it_says(capsys: pytest.CaptureFixture[str]) -> None:
    import re

    from doc_examples import code_blocks

    block = next(b for b in code_blocks("simulate.md") if "best_tied_policy(" in b)
    exec(compile(block, "simulate.md:how-the-learners-plan", "exec"), {})
    claimed = re.search(r"print\(.*\)\s+# (.*)", block).group(1).strip()
    assert capsys.readouterr().out.strip() == claimed
