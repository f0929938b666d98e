"""Hand-made curricula and test sets following docs/schemas.md, for the simulate tests.

Demonstrations are the robot's greedy optimal rollouts under w* (so they are optimal, as
every condition's demonstrations are); the schema's keys are filled in so the fixtures
look exactly like `cfteach teach` / `cfteach tests` output.
"""

from __future__ import annotations

import numpy as np

from cfteach.domains import Domain
from cfteach.mdp import compile_domain, greedy_actions, value_iteration


def make_demo(dom: Domain, env: int, state_index: int) -> dict:
    b = compile_domain(dom)
    q = value_iteration(b, dom.weights[None], env=[env]).Q[0, 0]
    pol = greedy_actions(q)
    inst = b.instances[env]
    state = b.states[env][state_index]
    acts, states, mu = [], [state], np.zeros(b.F)
    while True:
        a = int(pol[b.index_of(env, state)])
        state, phi, terminal = inst.step(state, a)
        acts.append(dom.actions[a])
        states.append(state)
        mu += phi
        if terminal:
            break
    json_states = [inst.state_to_json(x) for x in states]
    return {"env_code": list(inst.env_code), "env_index": env,
            "start_state": inst.state_to_json(b.states[env][state_index]), "actions": acts,
            "states": json_states, "feature_counts": [int(x) for x in mu],
            "reward": float(mu @ dom.weights), "constraints": []}


def make_curriculum(dom: Domain, condition: str, picks: list[tuple[int, int]]) -> dict:
    demos = [dict(make_demo(dom, e, s), knowledge_gain=1.0, belief_area_after=1.0,
                  masked_feature=None) for e, s in picks]
    return {"schema": "cfteach.curriculum/1", "domain": dom.name, "condition": condition,
            "profile": "default", "seed": 0, "settings": {}, "feature_names":
            list(dom.feature_names), "weights": list(map(float, dom.weights)),
            "prior": np.asarray(dom.prior).tolist(), "demos": demos,
            "final_belief": {"constraints": [], "area": 0.0}}


def make_tests(dom: Domain, picks: dict[str, list[tuple[int, int]]],
             candidates: list[tuple[int, int, float, int]] = ()) -> dict:
    tests = {}
    for level, lst in picks.items():
        tests[level] = []
        for k, (e, s) in enumerate(lst):
            d = make_demo(dom, e, s)
            tests[level].append(dict(d, overlap={"low": 1.5, "medium": 0.8, "high": 0.2}[level]
                                     + 0.01 * k, difficulty=level,
                                     all_optimal_actions=[d["actions"]],
                                     optimal_reward=d["reward"]))
    out = {"schema": "cfteach.tests/1", "domain": dom.name, "profile": "default", "seed": 0,
           "settings": {}, "feature_names": list(dom.feature_names),
           "weights": list(map(float, dom.weights)),
           "belief": {"constraints": np.asarray(dom.posterior).tolist(), "area": 1.0},
           "excluded": [], "cluster_centres": [0.2, 0.5, 0.8, 1.2, 1.5], "tests": tests}
    if candidates:
        b = compile_domain(dom)
        out["candidates"] = [
            {"env_code": list(b.instances[e].env_code), "env_index": e,
             "start_state": b.instances[e].state_to_json(b.states[e][s]), "overlap": ov,
             "cluster": cl} for e, s, ov, cl in candidates]
    return out
