"""Simulated learners: beliefs keep w*, teaching helps, constraints and answers are right."""

from __future__ import annotations

import numpy as np
import pytest

from cfteach.domains import load
from cfteach.mdp import compile_domain, greedy_actions, value_iteration
from cfteach.simulate.learners import LEARNER_MODELS, Learners, learner_model
from simulate_fixtures import make_demo

PICKS = {
    "tiles": [(511, 0), (255, 0), (480, 3), (15, 0), (300, 10)],
    "delivery": [(63, 0), (31, 5), (40, 20), (7, 50), (62, 3)],
    "skateboard": [(7, 0), (5, 3), (3, 100), (7, 200), (1, 10)],
}


def _tests(dom, n: int, seed: int) -> list[dict]:
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        e = int(rng.integers(len(dom.instances())))
        out.append(make_demo(dom, e, int(rng.integers(len(dom.instances()[e].states())))))
    return out


@pytest.mark.parametrize("name", ["tiles", "delivery", "skateboard"])
@pytest.mark.parametrize("model", ["counterfactual", "noisy", "irl"])
def test_taught_beliefs_contain_w_star(name: str, model: str) -> None:
    dom = load(name)
    learners = Learners(dom, model, 6, rng=3)
    learners.teach([make_demo(dom, e, s) for e, s in PICKS[name]])
    assert learners.contains(dom.weights).all()
    # ... and the demonstrations taught something: beliefs shrank below the prior's 2*pi
    assert (learners.belief_areas() < 2 * np.pi - 1e-6).any()


@pytest.mark.parametrize("name", ["tiles", "delivery"])
def test_no_demonstrations_does_worse_than_a_curriculum(name: str) -> None:
    dom = load(name)
    tests = _tests(dom, 16, seed=5)
    none = Learners(dom, "counterfactual", 24, rng=1).answer(tests)["correct"].mean()
    taught = Learners(dom, "counterfactual", 24, rng=1)
    taught.teach([make_demo(dom, e, s) for e, s in PICKS[name]])
    assert taught.answer(tests)["correct"].mean() > none + 0.1


def _independent_one_step(dom, demo: dict) -> set[tuple[int, ...]]:
    """One-action deviations by stepping the Instance itself (no compiled arrays)."""
    b = compile_domain(dom)
    env = demo["env_index"]
    inst = dom.instances()[env]
    q = value_iteration(b, dom.weights[None], env=[env]).Q[0, 0]
    pol = greedy_actions(q)

    def run(state, first=None) -> np.ndarray:
        mu = np.zeros(dom.n_features)
        for t in range(500):
            a = first if (t == 0 and first is not None) else int(pol[b.index_of(env, state)])
            state, phi, term = inst.step(state, a)
            mu += phi
            if term:
                return mu
        raise AssertionError("the optimal policy does not finish")

    state = inst.state_from_json(demo["start_state"])
    out = set()
    for name in demo["actions"]:
        a = dom.actions.index(name)
        opt = run(state)
        for alt in range(len(dom.actions)):
            if alt != a:
                c = opt - run(state, alt)
                if np.any(c):
                    out.add(tuple(int(x) for x in c))
        state = inst.step(state, a)[0]
    return out


@pytest.mark.parametrize("name", ["tiles", "delivery", "skateboard"])
def test_irl_constraints_equal_an_independent_replay(name: str) -> None:
    dom = load(name)
    learners = Learners(dom, "irl", 1, rng=0)
    for e, s in PICKS[name][:3]:
        demo = make_demo(dom, e, s)
        rows = learners._one_step_constraints(learners.replay(demo))
        got = {tuple(int(x) for x in r) for r in rows if np.any(r)}
        assert got == _independent_one_step(dom, demo)


def _tight_cone(w: np.ndarray, width: float = 0.01) -> np.ndarray:
    """Four float normals whose region is a tiny square cone around w."""
    u = np.linalg.svd(w[None])[2][1:]  # orthonormal complement of w
    rows = []
    for v in u[:2]:
        rows += [v + width * w, -v + width * w]
    for v in u[2:]:  # pin the remaining directions too (n > 3)
        rows += [v + width * w, -v + width * w]
    return np.array(rows)


@pytest.mark.parametrize("name", ["tiles", "delivery", "skateboard"])
def test_a_learner_who_knows_w_star_answers_every_test_optimally(name: str) -> None:
    dom = load(name)
    tests = _tests(dom, 12, seed=11)
    learners = Learners(dom, "counterfactual", 4, rng=0)
    learners.beliefs = [_tight_cone(dom.weights)] * 4
    got = learners.answer(tests)
    np.testing.assert_allclose(got["optimal_reward"], [t["reward"] for t in tests])
    assert got["finished"].all()
    assert got["correct"].all()
    # the same knowledge with very noisy hands does worse
    hot = Learners(dom, learner_model("noisy", temperature=1.0), 4, rng=0)
    hot.beliefs = [_tight_cone(dom.weights)] * 4
    assert hot.answer(tests)["correct"].mean() < 0.9


def test_unbounded_samples_are_redrawn_or_fail() -> None:
    dom = load("tiles")
    tests = _tests(dom, 12, seed=2)
    strict = Learners(dom, learner_model("counterfactual", unbounded="drop"), 16, rng=4)
    fin_strict = strict.answer(tests)["finished"]
    assert not fin_strict.all()  # prior samples with positive tile weights loop forever
    for rule in ("loops", "resample"):
        lenient = Learners(dom, learner_model("counterfactual", unbounded=rule), 16, rng=4)
        assert lenient.answer(tests)["finished"].all()


def test_loops_rule_learns_that_paying_loops_do_not_pay() -> None:
    dom = load("tiles")
    demo = make_demo(dom, 511, 0)  # every tile present: positive tile weights would loop
    areas = {}
    for rule in ("loops", "drop"):
        learners = Learners(dom, learner_model("counterfactual", unbounded=rule), 12, rng=0)
        learners.observe(demo)
        assert learners.contains(dom.weights).all()
        areas[rule] = learners.belief_areas()
        if rule == "loops":
            rows = np.vstack(learners.beliefs)
            # leaving an A (B) tile and coming back does not pay: -A - 2 step >= 0 etc.
            assert any(r[0] < 0 and r[1] == 0 for r in rows)
    assert areas["loops"].mean() < areas["drop"].mean()


def test_bad_input_is_named() -> None:
    dom = load("tiles")
    learners = Learners(dom, "counterfactual", 2, rng=0)
    demo = make_demo(dom, 5, 0)
    with pytest.raises(ValueError, match="unknown action 'jump'"):
        learners.observe(dict(demo, actions=["jump"]))
    with pytest.raises(ValueError, match="does not match env_index"):
        learners.observe(dict(demo, env_code=[1] * 9))
    with pytest.raises(ValueError, match="feature_counts"):
        learners.observe(dict(demo, feature_counts=[9, 9, 9]))
    with pytest.raises(ValueError, match="out of range"):
        no_code = {k: v for k, v in demo.items() if k != "env_code"}
        learners.observe(dict(no_code, env_index=10_000))
    with pytest.raises(ValueError, match="unknown learner model 'genius'"):
        learner_model("genius")
    with pytest.raises(ValueError, match="at least one learner"):
        Learners(dom, "irl", 0)
    assert set(LEARNER_MODELS) == {"counterfactual", "irl", "noisy", "inattentive"}
    with pytest.raises(ValueError, match="p_absorb"):
        learner_model("inattentive", p_absorb=0.0)


def test_more_than_three_features_end_to_end() -> None:
    from cfteach.domains.random import random_gridworld

    dom = random_gridworld(6, 6, 5, 16, 3)
    b = compile_domain(dom)
    # informative demos: long ones (the robot detours around costly cells)
    cands = [(e, s) for e in range(16) for s in range(len(b.states[e]))]
    lengths = {c: len(make_demo(dom, *c)["actions"]) for c in cands[::7]}
    picks = sorted(lengths, key=lambda c: -lengths[c])[:4]
    learners = Learners(dom, "counterfactual", 4, rng=0)
    learners.teach([make_demo(dom, e, s) for e, s in picks])
    assert learners.contains(dom.weights).all()
    area, se = learners.belief_area_estimates(n_samples=4000)
    half_sphere = 8 * np.pi ** 2 / 3 / 2  # area of S^4 is 8 pi^2 / 3
    assert np.all(area <= half_sphere * 1.01) and np.all(se >= 0)
    got = learners.answer([make_demo(dom, e, s) for e, s in cands[1::9][:6]])
    assert got["correct"].shape == (4, 6) and got["finished"].all()


@pytest.mark.slow
def test_real_proposed_curriculum_keeps_w_star_and_beats_no_teaching() -> None:
    from cfteach.teaching import select_tests, teach

    dom = load("skateboard")
    cur = teach(dom, "proposed", seed=0)
    tests = select_tests(dom, training=[cur], seed=0, per_level=6).to_json()["tests"]
    flat = [t for level in ("low", "medium", "high") for t in tests[level]]
    taught = Learners(dom, "counterfactual", 16, rng=0)
    taught.teach(cur.to_json()["demos"])
    assert taught.contains(dom.weights).all()
    assert (taught.belief_areas() < 2 * np.pi).all()
    none = Learners(dom, "counterfactual", 16, rng=0)
    assert taught.answer(flat)["correct"].mean() > none.answer(flat)["correct"].mean() + 0.1


def test_learner_specs_from_the_command_line() -> None:
    m = learner_model("noisy:temperature=0.1:human_models=3:unbounded=drop:all_suffixes=1")
    assert (m.temperature, m.human_models, m.unbounded, m.all_suffixes) == (0.1, 3, "drop", True)
    assert m.name == "noisy:temperature=0.1:human_models=3:unbounded=drop:all_suffixes=1"
    assert learner_model("irl").name == "irl"
    with pytest.raises(ValueError, match="bad learner option 'speed=2'"):
        learner_model("noisy:speed=2")
    with pytest.raises(ValueError, match="bad value 'hot' for temperature"):
        learner_model("noisy:temperature=hot")
    with pytest.raises(ValueError, match="temperature must be >= 0"):
        learner_model("noisy:temperature=-1")
    with pytest.raises(ValueError, match="unbounded must be one of loops, resample, drop"):
        learner_model("noisy:unbounded=ignore")


@pytest.mark.parametrize("model", ["counterfactual", "noisy"])
def test_answer_moves_replay_to_the_same_feature_counts(model):
    """`answer(moves=True)` returns the moves behind each answer (what the closed-loop
    teacher sees), drawn with the same random numbers as without them."""
    from cfteach.domains import load as load_domain
    from cfteach.simulate.learners import Learners

    dom = load_domain("skateboard")
    tests = [{"env_index": 0, "start_state": dom.instances()[0].state_to_json(s)}
             for s in dom.instances()[0].states()[:4]]
    a = Learners(dom, model, 3, rng=7).answer(tests, moves=True)
    b = Learners(dom, model, 3, rng=7).answer(tests)
    assert np.array_equal(a["feature_counts"], b["feature_counts"])
    batch = Learners(dom, model, 1, rng=0).batch
    for i in range(3):
        for j, t in enumerate(tests):
            s = batch.index_of(0, dom.instances()[0].state_from_json(t["start_state"]))
            mu = np.zeros(batch.F)
            for name in a["actions"][i][j]:
                k = batch.actions.index(name)
                mu += batch.features[0, s, k]
                s = int(batch.next_state[0, s, k])
            assert np.allclose(mu, a["feature_counts"][i, j])
            assert (s == batch.sink) == bool(a["finished"][i, j])


def _p_optimal_by_dp(batch, env: int, w: np.ndarray, temperature: float) -> np.ndarray:
    """P(a Boltzmann player who knows `w` ends on an optimal path) from every state,
    by dynamic programming over the MDP: p(s) = sum over optimal a of pi(a|s) p(next)."""
    q = value_iteration(batch, w[None], env=[env]).Q[0, 0]
    optimal = q >= q.max(axis=-1, keepdims=True) - 1e-9
    logits = q / temperature
    pi = np.exp(logits - logits.max(axis=-1, keepdims=True))
    pi /= pi.sum(axis=-1, keepdims=True)
    nxt, sink = batch.next_state[env], batch.sink
    p = np.zeros(nxt.shape[0])
    for _ in range(4 * nxt.shape[0]):
        p = (pi * optimal * p[nxt]).sum(axis=-1)
        p[sink] = 1.0
    return p


@pytest.mark.parametrize(("env", "state"), [(30, 51), (2, 14)])
def test_expected_correct_matches_dynamic_programming(env: int, state: int) -> None:
    """A noisy learner who knows w*: its expected P(optimal) on a test equals the exact
    probability that Boltzmann play takes optimal actions only (within 4 standard errors
    of the Monte Carlo estimate)."""
    dom = load("delivery")
    temperature, draws = 0.1, 1500
    learners = Learners(dom, learner_model("noisy", temperature=temperature), 1, rng=3)
    learners.beliefs = [_tight_cone(dom.weights, 1e-4)]
    w = np.array(dom.weights, dtype=float) / np.linalg.norm(dom.weights)
    exact = _p_optimal_by_dp(learners.batch, env, w, temperature)
    test = make_demo(dom, env, state)
    s = learners.batch.index_of(env, dom.instances()[env].state_from_json(test["start_state"]))
    assert 0.05 < exact[s] < 0.95  # a state where the estimate is not trivially 0 or 1
    est = learners.expected_correct([test], draws)[0]
    se = np.sqrt(exact[s] * (1 - exact[s]) / draws)
    assert abs(est - exact[s]) < 4 * se


def test_expected_correct_edge_cases() -> None:
    dom = load("skateboard")
    learners = Learners(dom, "noisy", 2, rng=0)
    assert np.isnan(learners.expected_correct([])).all()
    with pytest.raises(ValueError, match="draws must be >= 1"):
        learners.expected_correct(_tests(dom, 2, seed=0), 0)
    with pytest.raises(ValueError, match="one play per test"):
        learners._play(_tests(dom, 2, seed=0), 2, moves=True)
