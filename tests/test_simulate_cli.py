"""`cfteach simulate` end to end on a small reproduce-style folder."""

from __future__ import annotations

import json

import pytest

from cfteach.cli import app
from cfteach.domains import load
from cli_runner import WideRunner
from simulate_fixtures import make_curriculum, make_tests


def _folder(tmp_path):
    dom = load("tiles")
    (tmp_path / "in" / "tiles").mkdir(parents=True)
    cur = make_curriculum(dom, "proposed", [(511, 0), (255, 0), (480, 3)])
    (tmp_path / "in" / "tiles" / "proposed.json").write_text(json.dumps(cur))
    tests = make_tests(dom, {"low": [(0, 0)], "medium": [(100, 4)], "high": [(511, 1)]})
    (tmp_path / "in" / "tiles" / "tests.json").write_text(json.dumps(tests))
    return tmp_path / "in"


def test_simulate_command_writes_results(tmp_path) -> None:
    src = _folder(tmp_path)
    out = tmp_path / "out"
    res = WideRunner().invoke(app, ["simulate", "--domains", "tiles", "--conditions",
                                   "proposed,none", "--learner", "counterfactual",
                                   "--learners", "4", "--workers", "1", "--from", str(src),
                                   "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert "learner model: counterfactual" in res.output and "H1" in res.output
    data = json.loads((out / "results.json").read_text())
    assert {r["condition"] for r in data["proportion_optimal"]} == {"proposed", "none"}
    assert (out / "proportion_optimal_tiles.png").exists()


def test_simulate_command_names_bad_input(tmp_path) -> None:
    src = _folder(tmp_path)
    runner = WideRunner()
    res = runner.invoke(app, ["simulate", "-d", "tiles", "-c", "proposed,telepathy",
                              "--from", str(src), "--out", str(tmp_path / "o")])
    assert res.exit_code == 2 and "unknown condition(s) ['telepathy']" in res.output
    res = runner.invoke(app, ["simulate", "-d", "tiles", "--backend", "spark",
                              "--from", str(src), "--out", str(tmp_path / "o")])
    assert res.exit_code == 2 and "unknown parallel backend 'spark'" in res.output
    res = runner.invoke(app, ["simulate", "-d", "tiles", "-c", "baseline",
                              "--from", str(src), "--out", str(tmp_path / "o")])
    assert res.exit_code == 2 and "baseline" in res.output


@pytest.mark.slow
def test_simulate_random_four_feature_domain_end_to_end(tmp_path) -> None:
    """n > 3 features through teaching, test selection, learners and the summary."""
    out = tmp_path / "out"
    res = WideRunner().invoke(app, ["simulate", "-d", "random:5x5:f4:n8:s1", "-c",
                                   "proposed,none", "-l", "counterfactual", "-n", "4",
                                   "--workers", "1", "--out", str(out)])
    assert res.exit_code == 0, res.output
    data = json.loads((out / "results.json").read_text())
    assert data["settings"]["domains"] == ["random-5x5-f4-n8-s1"]
    beliefs = {b["condition"]: b for b in data["beliefs"]}
    assert beliefs["proposed"]["contains_w_star"] == 1.0
    # beyond 3 features the belief area is an estimate with a standard error
    assert beliefs["proposed"]["mean_belief_area_se"] is not None
    assert beliefs["none"]["mean_belief_area"] > beliefs["proposed"]["mean_belief_area"]
