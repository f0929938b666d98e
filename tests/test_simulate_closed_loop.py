"""`cfteach simulate` with closed_loop: regret, items shown and the equal-budget control."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from cfteach.cli import app
from cfteach.simulate.summary import regret_table
from cfteach.simulate.sweep import run_sweep
from cli_runner import WideRunner


@pytest.fixture(scope="module")
def sweep():
    return run_sweep(["skateboard"], ["proposed", "closed_loop"], ["inattentive"],
                     n_learners=4, seed=1, per_level=2, chunk_learners=2,
                     teacher={"n_particles": 200, "max_items": 12})


def test_results_carry_regret_and_items_for_every_condition(sweep):
    summ = sweep.summary()
    conds = {"proposed", "closed_loop", "proposed_equal_budget"}
    assert set(summ["regret"]["inattentive"]["skateboard"]) == conds
    assert set(summ["items_shown"]["inattentive"]["skateboard"]) == conds
    for c in conds:
        r = summ["regret"]["inattentive"]["skateboard"][c]
        assert r["n_learners"] == 4 and r["ci_low"] <= r["mean"] <= r["ci_high"]
    items = summ["items_shown"]["inattentive"]["skateboard"]
    cl = items["closed_loop"]
    assert cl["max"] <= 12
    assert cl["mean"] == pytest.approx(cl["demonstrations"] + cl["tests"] + cl["feedback"])
    # the control shows as many demonstrations as closed-loop showed demonstrations + feedback
    b = sweep.beliefs[sweep.beliefs["condition"] == "closed_loop"]
    budget = int(round(float((b["demos"] + b["feedback"]).mean())))
    assert items["proposed_equal_budget"]["demonstrations"] == budget
    assert items["proposed"]["tests"] == 0 and items["proposed"]["feedback"] == 0


def test_same_held_out_tests_in_every_condition(sweep):
    a = sweep.answers
    tests = {c: sorted(g["test"].unique()) for c, g in a.groupby("condition")}
    assert tests["closed_loop"] == tests["proposed"] == tests["proposed_equal_budget"]


def test_regret_table_against_a_hand_computation():
    rows = []
    rng = np.random.default_rng(0)
    for learner in range(5):
        for t in range(3):
            opt = -2.0 - t
            reward = opt - rng.choice([0.0, 0.5, 3.0])
            rows.append({"learner_model": "m", "domain": "d", "condition": "c", "seed": 0,
                         "learner": learner, "test": t, "reward": reward,
                         "optimal_reward": opt, "finished": True})
    rows.append({**rows[0], "test": 9, "reward": rows[0]["optimal_reward"] + 1e-12})
    df = pd.DataFrame(rows)
    per_learner = []
    for learner in range(5):
        mine = [max(0.0, r["optimal_reward"] - r["reward"]) for r in rows
                if r["learner"] == learner]
        per_learner.append(sum(mine) / len(mine))
    from scipy import stats

    m = float(np.mean(per_learner))
    half = stats.t.ppf(0.975, 4) * np.std(per_learner, ddof=1) / np.sqrt(5)
    got = regret_table(df)["m"]["d"]["c"]
    assert got["mean"] == pytest.approx(m)
    assert got["ci_high"] == pytest.approx(m + half)
    assert got["ci_low"] == pytest.approx(max(0.0, m - half))
    assert got["n_learners"] == 5


def test_cli_rejects_bad_teacher_settings_before_work(tmp_path: Path):
    res = WideRunner().invoke(app, ["simulate", "-d", "skateboard", "-c", "closed_loop",
                                   "--teacher", "max_items=0", "--out", str(tmp_path)])
    assert res.exit_code == 2
    assert "max_items" in " ".join(res.output.split())
    assert not (tmp_path / "results.json").exists()


def test_teach_names_closed_loop(tmp_path: Path):
    res = WideRunner().invoke(app, ["teach", "skateboard", "--condition", "closed_loop"])
    assert res.exit_code != 0
    assert "no fixed curriculum" in " ".join(res.output.split())


def test_written_results_are_strict_json(sweep, tmp_path: Path):
    sweep.write(tmp_path)
    data = json.loads((tmp_path / "results.json").read_text())
    assert "regret" in data and "items_shown" in data
    assert "optimal_reward" in pd.read_csv(tmp_path / "answers.csv").columns
