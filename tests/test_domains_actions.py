"""Declared actions (move / pickup / dropoff / exit / stay), the `to_cells`, `cargo_at` and
`not` conditions, and the 2021 augmented taxi written with them (examples/domains/)."""

from __future__ import annotations

import copy
import json
import math
from pathlib import Path

import numpy as np
import pytest

from cfteach.cli import app
from cfteach.domains import DomainFileError, from_dict, load
from cfteach.domains.spec import BUILTIN_ACTIONS, ActionSpec, load_toml
from cli_runner import WideRunner

ROOT = Path(__file__).resolve().parents[1]
TAXI = ROOT / "examples" / "domains" / "augmented_taxi_2021.toml"


def _taxi() -> dict:
    return load_toml(TAXI)


def _with(mutate) -> dict:
    data = copy.deepcopy(_taxi())
    mutate(data)
    return data


def _set_actions(acts: list) -> object:
    def f(d: dict) -> None:
        d["domain"]["actions"] = acts
    return f


def _set_when(feature: int, when: dict) -> object:
    def f(d: dict) -> None:
        d["features"][feature].pop("any", None)
        d["features"][feature]["when"] = when
    return f


EXIT = {"name": "exit", "key": "x", "effect": "exit"}


@pytest.mark.parametrize(("mutate", "key", "problem"), [
    (_set_actions(["up", EXIT, {"name": "exit", "key": "y", "effect": "stay"}]),
     "domain.actions[2].name", "twice"),
    (_set_actions(["up", EXIT, {"name": "wait", "key": "x", "effect": "stay"}]),
     "domain.actions[2].key", "already bound to action 'exit'"),
    (_set_actions(["up", {"name": "wait", "key": "p", "effect": "stay"}, "pickup"]),
     "domain.actions[2]", "already bound to action 'wait'"),
    (_set_actions([{"name": "fly", "key": "f", "effect": "teleport"}]),
     "domain.actions[0].effect", "unknown effect 'teleport'"),
    (_set_actions([{"name": "hop", "key": "h", "effect": "move"}]),
     "domain.actions[0].delta", "a move needs delta"),
    (_set_actions([{"name": "hop", "key": "h", "effect": "move", "delta": [0, 0]}]),
     "domain.actions[0].delta", "must not be [0, 0]"),
    (_set_actions([{"name": "hop", "key": "h", "effect": "move", "delta": [1]}]),
     "domain.actions[0].delta", "two integers"),
    (_set_actions([{"name": "wait", "key": "w", "effect": "stay", "delta": [1, 0]}]),
     "domain.actions[0].delta", "only a move has a delta"),
    (_set_actions([{"name": "wait", "effect": "stay"}]),
     "domain.actions[0].key", "missing required key"),
    (_set_actions([{"name": "wait", "key": "w"}]),
     "domain.actions[0].effect", "missing required key"),
    (_set_actions([{"name": "move", "key": "m", "effect": "stay"}]),
     "domain.actions[0].name", "reserved"),
    (_set_actions([{"name": "wait", "key": "w", "effect": "stay", "colour": 1}]),
     "domain.actions[0].colour", "unknown key"),
    (_set_actions([{"name": "wait", "key": "wait", "effect": "stay"}]),
     "domain.actions[0].key", "one character or a key name"),
    (_set_actions([{"name": "wait", "key": "", "effect": "stay"}]),
     "domain.actions[0].key", "one character or a key name"),
    (_set_actions([{"name": "wait", "key": 7, "effect": "stay"}]),
     "domain.actions[0].key", "one character or a key name"),
    (_set_actions(["jump"]), "domain.actions[0]", "unknown action 'jump'"),
    (_set_actions([]), "domain.actions", "at least one action"),
    (_set_when(2, {"action": "quit"}), "features[2].when.action[0]", "unknown action 'quit'"),
    (_set_when(1, {"to_cells": "tolls"}), "features[1].when.to_cells", "unknown cell set"),
    (_set_when(0, {"cargo_at": [[1, 2]]}), "features[0].when.cargo_at[0]", "on a wall"),
    (_set_when(0, {"cargo_at": []}), "features[0].when.cargo_at", "at least one cell"),
    (_set_when(0, {"cargo_at": "nowhere"}), "features[0].when.cargo_at", "unknown cell set"),
    (_set_when(2, {"not": {"action": "exit", "flying": True}}), "features[2].when.not.flying",
     "unknown key"),
])
def test_bad_actions_and_conditions_name_the_key(mutate, key: str, problem: str) -> None:
    with pytest.raises(DomainFileError) as exc:
        from_dict(_with(mutate), source="bad.toml")
    assert exc.value.key == key, str(exc.value)
    assert problem in str(exc.value), str(exc.value)


def test_cargo_at_needs_a_cargo() -> None:
    data = load_toml(ROOT / "src/cfteach/domains/data/tiles.toml")
    data["features"][0]["when"] = {"cargo_at": [[1, 1]]}
    with pytest.raises(DomainFileError) as exc:
        from_dict(data, source="t.toml")
    assert exc.value.key == "features[0].when.cargo_at" and "needs a [cargo]" in str(exc.value)


def test_declared_actions_keep_their_order_and_records() -> None:
    dom = from_dict(_with(_set_actions([
        {"name": "wait", "label": "wait a turn", "key": " ", "effect": "stay"},
        "left", {"name": "up", "key": "k"}, EXIT, "right", "down", "pickup", "dropoff"])))
    assert dom.actions == ("wait", "left", "up", "exit", "right", "down", "pickup", "dropoff")
    specs = {a.name: a for a in dom.action_specs}
    assert specs["wait"].label == "wait a turn" and specs["wait"].effect == "stay"
    assert specs["wait"].key == " "  # the space bar
    assert specs["up"] == ActionSpec("up", "move up", "k", "move", (0, 1))
    assert specs["left"] == BUILTIN_ACTIONS["left"]
    assert specs["exit"].label == "exit"  # the label defaults to the name


def test_exit_ends_from_any_state_and_stay_stays() -> None:
    dom = from_dict(_with(_set_actions(
        ["up", "left", "pickup", "dropoff", {"name": "wait", "key": "w", "effect": "stay"},
         EXIT])))
    inst = dom.instance(0)
    ex, wait = dom.actions.index("exit"), dom.actions.index("wait")
    for s in inst.states():
        nxt, _, term = inst.step(s, ex)
        assert term and nxt == s
        nxt, phi, term = inst.step(s, wait)
        assert nxt == s and not term
        assert phi.tolist() == [0.0, 0.0, 1.0]  # a stay pays the step, never a toll


def test_taxi_features_fire_as_the_issue_describes() -> None:
    dom = load(TAXI)
    a = {n: i for i, n in enumerate(dom.actions)}
    inst = dom.instance([1, 0, 0, 0, 0, 0, 1, 1])  # tolls at (2, 3), (2, 1), (3, 1)
    s0 = inst.initial_state
    assert s0 == (4, 1, 4, 1, 0) and inst.complexity == 3
    # exit with the passenger at (4, 1) (held or not) costs nothing; elsewhere one step.
    assert inst.step(s0, a["exit"])[1].tolist() == [0, 0, 0]
    held = inst.step(s0, a["pickup"])[0]
    assert held == (4, 1, 4, 1, 1)
    assert inst.step(held, a["exit"])[1].tolist() == [0, 0, 0]
    on_toll, phi, _ = inst.step(held, a["left"])
    assert on_toll[:2] == (3, 1) and phi.tolist() == [0, 1, 1]  # entering a toll
    assert inst.step(on_toll, a["exit"])[1].tolist() == [0, 0, 1]
    nxt, phi, _ = inst.step(on_toll, a["left"])  # into (2, 1), another toll
    assert phi.tolist() == [0, 1, 1]
    assert inst.step(nxt, a["dropoff"])[1].tolist() == [0, 0, 1]  # toll cells charge on entry
    assert inst.step(nxt, a["up"])[1].tolist() == [0, 0, 1]  # (2, 2) is free here
    at_dest, phi, term = inst.step(nxt, a["left"])
    assert phi.tolist() == [0, 0, 1] and not term
    _, phi, term = inst.step(at_dest, a["dropoff"])
    assert phi.tolist() == [1, 0, 1] and term
    bumped, phi, _ = inst.step(s0, a["right"])  # off the grid: no move, a step
    assert bumped == s0 and phi.tolist() == [0, 0, 1]


def test_taxi_counts_through_the_cli() -> None:
    res = WideRunner().invoke(app, ["domains", str(TAXI), "--json"])
    assert res.exit_code == 0, res.output
    info = json.loads(res.output)[0]
    assert (info["instances"], info["demonstrations"]) == (256, 25600)
    assert info["feature_names"] == ["delivered", "toll", "step"]
    assert np.allclose(info["weights"], np.array([26, -3, -1]) / math.sqrt(686))


def test_taxi_passes_check() -> None:
    res = WideRunner().invoke(app, ["check", str(TAXI)])
    assert res.exit_code == 0, res.output
    assert "256" in res.output


def _primitive(rows: np.ndarray) -> set[tuple[int, ...]]:
    out = set()
    for r in np.asarray(rows, dtype=np.int64):
        g = int(np.gcd.reduce(np.abs(r)))
        out.add(tuple(int(v) for v in r // max(g, 1)))
    return out


def _slice_grid(w_step: float, n: int = 801) -> np.ndarray:
    """Points (w0, w1, w_step) of a dense grid on the slice |w0| + |w1| <= 1 - |w_step|."""
    r = 1 - abs(w_step)
    u = np.linspace(-r, r, n)
    g = np.stack(np.meshgrid(u, u, indexing="ij"), axis=-1).reshape(-1, 2)
    g = g[np.abs(g).sum(axis=1) <= r]
    return np.c_[g, np.full(len(g), w_step)]


def test_taxi_policy_bec_is_the_original_two_constraints() -> None:
    """The original's shipped policy BEC: [1, 5, 11] and [-1, -6, -9]. Its learners were told
    the step cost, so its BEC is reduced on that slice: `policy_bec(known=["step"])`. On the
    sphere the cone also keeps [0, 1, -4] and [1, 6, 8]. Checked by brute force on a grid of
    the slice: every kept row cuts points the other kept row allows, and no dropped row cuts a
    point the kept rows allow."""
    from cfteach.bec import policy_bec

    dom = load(TAXI)
    sphere = policy_bec(dom)
    sliced = policy_bec(dom, known=["step"])
    assert _primitive(sliced) == {(1, 5, 11), (-1, -6, -9)}
    assert _primitive(sphere) == {(1, 5, 11), (-1, -6, -9), (0, 1, -4), (1, 6, 8)}
    pts = _slice_grid(-1 / 30)
    vals = pts @ sliced.T
    for i in range(len(sliced)):
        others = np.delete(vals, i, axis=1)
        assert np.any((others >= 0).all(axis=1) & (vals[:, i] < -1e-3))  # row i cuts
    inside = (vals >= 0).all(axis=1)
    assert inside.sum() > 20  # a thin wedge, but many grid points
    for row in sphere:
        assert (pts[inside] @ row >= -1e-9).all()  # every sphere row holds on the slice


def test_policy_bec_known_names_an_unknown_feature() -> None:
    from cfteach.bec import policy_bec

    with pytest.raises(ValueError, match="unknown feature.*'speed'"):
        policy_bec(load(TAXI), known=["speed"])


def _replayed_mu(inst, start, first: int, policy: np.ndarray, index) -> np.ndarray:
    """Feature counts of: `first`, then the greedy policy, by `Instance.step` (the taxi's
    optimal policy never stands still, so no self-loop rule is needed), at most 25 steps."""
    state, phi, term = inst.step(start, first)
    mu = np.rint(phi).astype(np.int64)
    for _ in range(24):
        if term:
            break
        state, phi, term = inst.step(state, int(policy[index(state)]))
        mu += np.rint(phi).astype(np.int64)
    return mu


def test_taxi_one_step_constraints_against_replays() -> None:
    """Every demo gets its one-step set, each keeps w*; sampled first-step rows equal the
    feature counts replayed state by state with `Instance.step`."""
    from cfteach.bec.constraints import one_action_rows
    from cfteach.bec.demos import demo_set
    from cfteach.teaching.common import one_step_sets

    dom = load(TAXI)
    ds = demo_set(dom, "default")
    sets = one_step_sets(ds)
    assert ds.D == 25600 and sorted(sets) == list(range(ds.D))
    w = np.asarray(dom.weights)
    assert all((rows @ w >= -1e-9).all() for rows in sets.values() if len(rows))
    first = one_action_rows(ds, first_step_only=True)
    for d in range(0, ds.D, 211):
        inst, start, e = ds.instance(d), ds.start_state(d), int(ds.env[d])
        pol = ds.policy[e]

        def index(s, e=e):
            return ds.batch.index_of(e, s)

        opt = _replayed_mu(inst, start, int(pol[index(start)]), pol, index)
        rows = [opt - _replayed_mu(inst, start, a, pol, index)
                for a in range(ds.batch.A) if a != int(pol[index(start)])]
        expect = {tuple(int(v) for v in r // int(np.gcd.reduce(np.abs(r)))) for r in rows
                  if np.any(r)}
        assert {tuple(r) for r in first.of(d).tolist()} == expect, (d, inst, start)
