"""Sweeps: same answers on every backend and worker count; JSON, CSV and figures written."""

from __future__ import annotations

import copy
import json
from functools import cache

import numpy as np
import pandas as pd
import pytest

from cfteach.domains import load
from cfteach.parallel import Executor
from cfteach.simulate.sweep import (
    Material,
    answer_items,
    load_material,
    parse_domain,
    simulate,
)
from simulate_fixtures import make_curriculum, make_tests


@cache
def _tiles_material() -> tuple[dict, dict]:
    dom = load("tiles")
    curricula = {
        "baseline": make_curriculum(dom, "baseline", [(15, 0), (480, 3)]),
        "proposed": make_curriculum(dom, "proposed", [(511, 0), (255, 0), (480, 3),
                                                      (300, 10)]),
    }
    tests = make_tests(dom, {"low": [(0, 0), (3, 2)], "medium": [(100, 4), (200, 6)],
                             "high": [(511, 1), (510, 7)]},
                       candidates=[(9, 1, 1.2, 4), (77, 5, 0.5, 2), (400, 3, 0.1, 0),
                                   (401, 3, 0.3, 1)])
    return curricula, tests


def _material(seed: int = 0) -> Material:
    curricula, tests = copy.deepcopy(_tiles_material())
    return Material("tiles", seed, curricula, tests)


def _run(executor=None, **kw) -> pd.DataFrame:
    res = simulate([_material()], ["counterfactual", "noisy"], n_learners=6,
                   conditions=["proposed", "none"], chunk_learners=3, seed=7,
                   executor=executor, **kw)
    return res.answers


@pytest.mark.slow
def test_local_one_and_two_workers_give_identical_answers() -> None:
    with Executor(n_workers=1) as one:
        a = _run(one)
    with Executor(n_workers=2) as two:
        b = _run(two)
    pd.testing.assert_frame_equal(a, b)
    assert len(a) == 2 * 2 * 6 * 6  # models x conditions x learners x tests


@pytest.mark.slow
def test_dask_local_cluster_gives_identical_answers() -> None:
    with Executor(n_workers=1) as one:
        a = _run(one)
    with Executor(backend="dask", n_workers=2) as ex:
        b = _run(ex)
    pd.testing.assert_frame_equal(a, b)


def test_other_seed_changes_answers_and_chunking_is_by_identity() -> None:
    a = simulate([_material()], ["noisy"], n_learners=8, conditions=["proposed"], seed=1,
                 chunk_learners=4).answers
    b = simulate([_material()], ["noisy"], n_learners=8, conditions=["proposed"], seed=2,
                 chunk_learners=4).answers
    assert not a["reward"].equals(b["reward"])
    # adding another condition to the sweep does not change this condition's learners
    c = simulate([_material()], ["noisy"], n_learners=8, conditions=["baseline", "proposed"],
                 seed=1, chunk_learners=4).answers
    pd.testing.assert_frame_equal(a.reset_index(drop=True),
                                  c[c["condition"] == "proposed"].reset_index(drop=True))


def test_candidates_become_tests_labelled_by_cluster() -> None:
    items = answer_items(_material().tests, include_candidates=True)
    cand = [i for i in items if i["source"] == "candidates"]
    assert [c["difficulty"] for c in cand] == ["low", "medium", "high", "other"]
    assert all(c["optimal_reward"] is None for c in cand)
    with pytest.raises(ValueError, match="no 'candidates'"):
        answer_items({"tests": {}}, include_candidates=True)


def test_write_produces_results_json_csv_and_figures(tmp_path) -> None:
    res = simulate([_material()], ["counterfactual"], n_learners=6,
                   conditions=["proposed", "none"], include_candidates=True, chunk_learners=3)
    summ = res.write(tmp_path)
    data = json.loads((tmp_path / "results.json").read_text())
    assert data["schema"] == "cfteach.simulation/1"
    assert {r["condition"] for r in data["proportion_optimal"]} == {"proposed", "none"}
    for r in data["proportion_optimal"]:
        assert 0 <= r["ci_low"] <= r["proportion_optimal"] <= r["ci_high"] <= 1 + 1e-12
        assert r["n_learners"] == 6 and r["n_answers"] == 12
    assert {r["source"] for r in data["h1"]} == {"selected", "candidates"}
    beliefs = {r["condition"]: r for r in data["beliefs"]}
    assert beliefs["proposed"]["contains_w_star"] == 1.0
    assert beliefs["none"]["mean_belief_area"] == pytest.approx(2 * np.pi)
    assert (tmp_path / "proportion_optimal_tiles.png").exists()
    assert (tmp_path / "proportion_optimal_tiles.svg").exists()
    answers = pd.read_csv(tmp_path / "answers.csv")
    assert set(answers["source"]) == {"selected"} and len(answers) == 2 * 6 * 6
    cand = pd.read_csv(tmp_path / "candidates.csv")
    assert len(cand) == 2 * 4 and (cand["n_answers"] == 6).all()
    assert summ["figures"] == ["proportion_optimal_tiles.png", "proportion_optimal_tiles.svg"]


def test_material_is_read_from_a_reproduce_folder(tmp_path) -> None:
    mat = _material()
    (tmp_path / "tiles").mkdir()
    for cond, cur in mat.curricula.items():
        (tmp_path / "tiles" / f"{cond}.json").write_text(json.dumps(cur))
    (tmp_path / "tiles" / "tests.json").write_text(json.dumps(mat.tests))
    got = load_material(tmp_path, ["tiles"], ["baseline", "proposed", "none"])
    assert got[0].curricula == mat.curricula and got[0].tests == mat.tests
    with pytest.raises(FileNotFoundError, match="feature_only"):
        load_material(tmp_path, ["tiles"], ["feature_only"])
    (tmp_path / "tiles" / "tests.json").write_text(json.dumps({"schema": "other"}))
    with pytest.raises(ValueError, match="expected schema 'cfteach.tests/1'"):
        load_material(tmp_path, ["tiles"], ["baseline"])


def test_domain_references() -> None:
    assert parse_domain("delivery") == "delivery"
    assert parse_domain("random:10x8:f5:n64:s3") == ("random", 10, 8, 5, 64, 3)
    with pytest.raises(ValueError, match="random:WxH:fF:nN:sS"):
        parse_domain("random:10x8:f5")
