"""`cfteach simulate` with closed_loop: regret, items shown, the equal-budget and equal-items
controls, ratios and calibration."""

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
    conds = {"proposed", "closed_loop", "proposed_equal_budget", "proposed_equal_items"}
    assert set(summ["regret"]["inattentive"]["skateboard"]) == conds
    assert set(summ["items_shown"]["inattentive"]["skateboard"]) == conds
    for c in conds:
        r = summ["regret"]["inattentive"]["skateboard"][c]
        assert r["n_learners"] == 4 and r["ci_low"] <= r["mean"] <= r["ci_high"]
        assert 0 <= r["p_optimal"] <= 1 and r["median"] >= 0
    items = summ["items_shown"]["inattentive"]["skateboard"]
    cl = items["closed_loop"]
    assert cl["max"] <= 12
    assert cl["mean"] == pytest.approx(cl["demonstrations"] + cl["tests"] + cl["feedback"])
    # the control shows as many demonstrations as closed-loop showed demonstrations + feedback
    b = sweep.beliefs[sweep.beliefs["condition"] == "closed_loop"]
    budget = int(round(float((b["demos"] + b["feedback"]).mean())))
    assert items["proposed_equal_budget"]["demonstrations"] == budget
    assert items["proposed"]["tests"] == 0 and items["proposed"]["feedback"] == 0


def test_equal_items_control_shows_each_learner_as_many_items_as_its_session(sweep):
    b = sweep.beliefs
    closed = b[b["condition"] == "closed_loop"].set_index("learner")["items"]
    same = b[b["condition"] == "proposed_equal_items"].set_index("learner")
    assert sorted(same.index) == sorted(closed.index)
    for learner, n in closed.items():
        assert same.loc[learner, "items"] == n == same.loc[learner, "demos"]


def test_calibration_and_ratios_are_well_formed(sweep):
    summ = sweep.summary()
    cal = summ["calibration"]["inattentive"]["skateboard"]
    assert set(cal) >= {"predicted", "observed", "n"} and cal["n"] == 4
    assert 0 <= cal["predicted"] <= 1 and 0 <= cal["observed"] <= 1
    # observed: the learners' own post-test P(optimal), recomputed from the answers
    a = sweep.answers
    per = a[a["condition"] == "closed_loop"].groupby("learner")["correct"].mean()
    assert cal["observed"] == pytest.approx(float(per.mean()))
    pred = sweep.beliefs.loc[sweep.beliefs["condition"] == "closed_loop", "predicted"]
    assert cal["predicted"] == pytest.approx(float(pred.mean()))
    # the learners' P(optimal) on the teacher's own probes: closed loop only, in [0, 1]
    b = sweep.beliefs
    on_probes = b.loc[b["condition"] == "closed_loop", "probe_observed"].to_numpy(float)
    assert np.all((on_probes >= 0) & (on_probes <= 1))
    assert np.isnan(b.loc[b["condition"] == "proposed", "probe_observed"]).all()
    assert cal["observed_on_probes"] == pytest.approx(float(on_probes.mean()))
    # the learners' expected post-test score (many plays of each): closed loop only
    expected = b.loc[b["condition"] == "closed_loop", "expected"].to_numpy(float)
    assert np.all((expected >= 0) & (expected <= 1))
    assert np.isnan(b.loc[b["condition"] == "proposed", "expected"]).all()
    assert cal["expected"] == pytest.approx(float(expected.mean()))
    cells = summ["ratios"]["cells"]["inattentive"]["skateboard"]
    assert set(cells) == {"closed_loop/proposed", "closed_loop/proposed_equal_budget",
                          "closed_loop/proposed_equal_items"}
    reg = summ["regret"]["inattentive"]["skateboard"]
    for key, r in cells.items():
        den = reg[key.split("/")[1]]["mean"]
        if den > 0:
            assert r["ratio"] == pytest.approx(reg["closed_loop"]["mean"] / den)
        assert r["ci_low"] <= r["ratio"] <= r["ci_high"]


def test_same_held_out_tests_in_every_condition(sweep):
    a = sweep.answers
    tests = {c: sorted(g["test"].unique()) for c, g in a.groupby("condition")}
    assert tests["closed_loop"] == tests["proposed"] == tests["proposed_equal_budget"] \
        == tests["proposed_equal_items"]


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
