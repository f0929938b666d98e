"""The vectorised search that compiles a domain (`cfteach.domains.dynamics.explore`) against
an independent, slow, one-state-at-a-time reference written here from docs/domains.md:
same states in the same BFS order, same successor indices, same features, transition for
transition, and `Instance.step` agreeing with it state by state."""

from __future__ import annotations

from collections import deque
from pathlib import Path

import numpy as np
import pytest

from cfteach.domains import Instance, from_dict, load, random_gridworld
from cfteach.mdp import compile_instances

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "domains" / "augmented_taxi_2021.toml"


def _ref_terminal(inst: Instance, s: tuple[int, ...]) -> bool:
    spec = inst.domain.spec
    if spec.goal_kind == "agent_at":
        return (s[0], s[1]) == spec.goal
    return inst.cargo_present and s[4] == 0 and (s[2], s[3]) == spec.goal


def _ref_cond(inst: Instance, c, ctx: dict) -> bool:
    spec = inst.domain.spec
    if c.actions is not None and ctx["name"] not in c.actions:
        return False
    if c.moved is not None and ctx["moved"] != c.moved:
        return False
    if c.carrying is not None and ctx["held"] != c.carrying:
        return False
    if c.from_cells and ctx["cell"] not in inst.cells(c.from_cells):
        return False
    if c.leaves_cells and not (ctx["moved"] and ctx["cell"] in inst.cells(c.leaves_cells)):
        return False
    if c.to_cells and not (ctx["moved"] and ctx["new"] in inst.cells(c.to_cells)):
        return False
    if c.consumes:
        i = [n for n, _ in spec.consumables].index(c.consumes)
        if i not in ctx["consumed"]:
            return False
    if c.cargo_at is not None:
        cells = inst.cells(c.cargo_at) if isinstance(c.cargo_at, str) else c.cargo_at
        if not (inst.cargo_present and ctx["cargo"] in cells):
            return False
    return not any(_ref_cond(inst, n, ctx) for n in c.negated)


def ref_step(inst: Instance, state: tuple[int, ...], a: int):
    """The documented dynamics, one state at a time, in plain Python."""
    spec = inst.domain.spec
    n_f = len(spec.features)
    if _ref_terminal(inst, state):
        return state, [0] * n_f, True
    act = spec.action_specs[a]
    s = list(state)
    ax, ay = s[0], s[1]
    has_cargo = spec.cargo is not None
    held = bool(has_cargo and s[4])
    blocked = (inst.cells(spec.cargo.blocked_cells_when_carried)
               if has_cargo and spec.cargo.blocked_cells_when_carried else frozenset())
    if act.effect == "move":
        nx, ny = ax + act.delta[0], ay + act.delta[1]
        if (1 <= nx <= spec.width and 1 <= ny <= spec.height and (nx, ny) not in spec.walls
                and not (held and (nx, ny) in blocked)):
            s[0], s[1] = nx, ny
            if held:
                s[2], s[3] = nx, ny
    elif act.effect == "pickup":
        if inst.cargo_present and not held and (s[2], s[3]) == (ax, ay):
            s[4] = 1
    elif act.effect == "dropoff":
        if held:
            s[4] = 0
    moved = (s[0], s[1]) != (ax, ay)
    consumed = []
    off = 5 if has_cargo else 2
    if moved:
        for i, (_, cell) in enumerate(spec.consumables):
            if s[off + i] and cell == (ax, ay):
                s[off + i] = 0
                consumed.append(i)
    ctx = {"name": act.name, "moved": moved, "held": held, "cell": (ax, ay),
           "new": (s[0], s[1]), "consumed": consumed,
           "cargo": (state[2], state[3]) if has_cargo else None}
    phi = [0] * n_f
    for i, f in enumerate(spec.features):
        if any(phi[j] for j in f.unless):
            continue
        if not f.any_of or any(_ref_cond(inst, c, ctx) for c in f.any_of):
            phi[i] = 1
    nxt = tuple(s)
    return nxt, phi, act.effect == "exit" or _ref_terminal(inst, nxt)


def ref_compile(inst: Instance):
    """BFS from the initial state; transitions as (state list, {(i, a): (dest | -1, phi)})."""
    order = [inst.initial_state]
    index = {inst.initial_state: 0}
    queue = deque(order)
    while queue:
        s = queue.popleft()
        for a in range(len(inst.domain.actions)):
            nxt, _, term = ref_step(inst, s, a)
            if not term and nxt not in index:
                index[nxt] = len(order)
                order.append(nxt)
                queue.append(nxt)
    table = {}
    for i, s in enumerate(order):
        for a in range(len(inst.domain.actions)):
            nxt, phi, term = ref_step(inst, s, a)
            table[i, a] = (-1 if term else index[nxt], phi)
    return order, table


CUSTOM = {
    "domain": {"name": "custom", "width": 4, "height": 3, "walls": [[2, 2]],
               "actions": ["up", "right",
                           {"name": "jump", "key": "j", "effect": "move", "delta": [-2, 0]},
                           {"name": "wait", "key": "w", "effect": "stay"},
                           "pickup", "dropoff",
                           {"name": "quit", "key": "q", "effect": "exit"},
                           "left", "down"]},
    "cells": {"mud": [[3, 1]], "pad": [[4, 3]], "ice": []},
    "agent": {"start": [1, 1]},
    "cargo": {"name": "box", "start": [2, 1], "blocked_cells_when_carried": "pad"},
    "consumables": [{"name": "gem", "cell": [1, 3]}],
    "goal": {"cargo_delivered_at": [4, 1]},
    "variants": [{"add_cells": {"mud": [[2, 3]], "ice": [[3, 3]]}}, {"switch_on": ["gem"]}],
    "features": [
        {"name": "mud", "weight": -2, "when": {"to_cells": "mud"}},
        {"name": "ice", "weight": -1, "any": [{"leaves_cells": "ice"},
                                              {"cargo_at": "ice", "action": "wait"}]},
        {"name": "gem", "weight": 1, "when": {"consumes": "gem"}},
        {"name": "home", "weight": 0.5,
         "when": {"cargo_at": [[2, 1]], "not": {"action": ["quit", "wait"]}}},
        {"name": "step", "weight": -1, "unless": ["home"],
         "when": {"not": {"action": "quit", "carrying": False}}},
    ],
}


def _domains():
    yield from (load(n) for n in ("delivery", "tiles", "skateboard"))
    yield load(EXAMPLE)
    yield from_dict(CUSTOM)
    yield random_gridworld(6, 5, 4, 16, 1)
    yield random_gridworld(7, 6, 5, 32, 2)


@pytest.mark.parametrize("dom", list(_domains()), ids=lambda d: d.name)
def test_compile_matches_the_scalar_reference(dom) -> None:
    insts = dom.instances()
    insts = insts if len(insts) <= 16 else insts[:: len(insts) // 16]
    batch = compile_instances(insts)
    for e, inst in enumerate(insts):
        order, table = ref_compile(inst)
        assert list(batch.states[e]) == order
        assert int(batch.n_states[e]) == len(order)
        for (i, a), (dest, phi) in table.items():
            got = int(batch.next_state[e, i, a])
            assert got == (batch.sink if dest < 0 else dest), (inst, order[i], a)
            assert batch.features[e, i, a].tolist() == phi, (inst, order[i], a)
            nxt, step_phi, term = inst.step(order[i], a)
            ref_nxt, _, ref_term = ref_step(inst, order[i], a)
            assert (nxt, step_phi.tolist(), term) == (ref_nxt, phi, ref_term)
        assert inst.states() == order


def test_the_custom_domain_exercises_every_new_rule() -> None:
    """Guard against the equivalence test passing vacuously: each new rule fires somewhere."""
    dom = from_dict(CUSTOM)
    batch = compile_instances(dom.instances())
    fired = batch.features.reshape(-1, batch.F).sum(axis=0)
    assert (fired > 0).all(), dict(zip(dom.feature_names, fired.tolist(), strict=True))
    quit_ = dom.actions.index("quit")
    assert (batch.next_state[..., quit_][batch.valid] == batch.sink).all()
    wait = dom.actions.index("wait")
    s = np.arange(batch.S)[None, :]
    assert (batch.next_state[..., wait] == s)[batch.valid].all()


def test_prefetch_fills_the_same_states_as_one_instance_at_a_time() -> None:
    a, b = random_gridworld(6, 6, 4, 16, 5), random_gridworld(6, 6, 4, 16, 5)
    a.prefetch_states()
    assert [i.states() for i in a.instances()] == [ref_compile(i)[0] for i in b.instances()]
    assert a.n_demonstrations() == sum(len(ref_compile(i)[0]) for i in b.instances())


@pytest.mark.parametrize("dom", [load("delivery"), load(EXAMPLE), from_dict(CUSTOM)],
                         ids=lambda d: d.name)
def test_step_before_the_states_are_known_and_off_the_reachable_set(dom) -> None:
    """`Instance.step` answers from its table once the states are known, from the array step
    otherwise (a fresh instance, or a state no search reached): both equal the reference."""
    twin = type(dom).from_spec(dom.spec)  # same file, nothing cached
    for inst, fresh in list(zip(dom.instances(), twin.instances(), strict=True))[::7]:
        order, _ = ref_compile(inst)
        for s in order[:: max(1, len(order) // 12)]:
            for a in range(len(dom.actions)):
                nxt, phi, term = fresh.step(s, a)
                assert "_states" not in fresh.__dict__
                assert (nxt, phi.tolist(), term) == ref_step(inst, s, a)
        inst.states()
        goal = list(inst.initial_state)  # a terminal state: never in the table
        if dom.spec.goal_kind == "agent_at":
            goal[0:2] = dom.spec.goal
        else:
            goal[2:5] = [*dom.spec.goal, 0]
        goal = tuple(goal)
        assert goal not in order
        for a in range(len(dom.actions)):
            nxt, phi, term = inst.step(goal, a)
            stays = (goal, [0] * dom.n_features, True)
            assert (nxt, phi.tolist(), term) == ref_step(inst, goal, a) == stays
