"""Gymnasium environments over cfteach domains: the official checker, and rewards, features,
observations, starts and truncation checked against hand-worked examples from the spec."""

from __future__ import annotations

import math
import warnings

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from cfteach import gym as cgym
from cfteach.render import style as st

UP, DOWN, LEFT, RIGHT, PICKUP, DROPOFF = range(6)
DELIVERY_NORM = math.sqrt(3**2 + 3.5**2 + 1**2)  # |[-3, 3.5, -1]|
TILES_NORM = math.sqrt(6.5**2 + 5.25**2 + 1**2)  # |[-6.5, -5.25, -1]|


@pytest.mark.parametrize("domain", ["delivery", "tiles", "skateboard"])
@pytest.mark.parametrize("render_mode", ["ansi", "rgb_array"])
def test_gymnasium_checker_passes_without_warnings(domain, render_mode):
    for env_code in (0, -1, "random-start"):
        kwargs = {}
        if env_code == "random-start":
            env_code, kwargs = 1, {"start_state": "random"}
        n = len(cgym.make(domain, 0).domain.instances())
        env = gymnasium.make(
            cgym.ENV_ID,
            domain=domain,
            env_code=env_code % n,
            render_mode=render_mode,
            **kwargs,
        )
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # any checker warning fails the test
            check_env(env.unwrapped)


def test_delivery_rewards_are_w_dot_features_by_hand():
    # b4 switches on mud at (3, 1); start: agent (2, 1), package at (4, 2), no station
    env = cgym.make("delivery", "000010")
    obs, info = env.reset(seed=0)
    assert obs == 0  # the initial state is the first reachable state
    assert info["state"] == {
        "agent": [2, 1],
        "passenger": [4, 2],
        "carrying": False,
        "station": False,
    }
    obs, r, term, trunc, info = env.step(RIGHT)  # into the mud: only a step
    assert info["features"].tolist() == [0, 0, 1]
    assert r == pytest.approx(-1 / DELIVERY_NORM, abs=1e-12)
    assert info["state"]["agent"] == [3, 1] and info["action"] == "right"
    obs, r, term, trunc, info = env.step(RIGHT)  # out of the mud: mud + step
    assert info["features"].tolist() == [1, 0, 1]
    assert r == pytest.approx((-3 - 1) / DELIVERY_NORM, abs=1e-12)
    obs, r, *_, info = env.step(UP)  # onto the package's cell
    obs, r, *_, info = env.step(PICKUP)
    assert info["state"]["carrying"] is True
    assert env.state_of(obs) == env.instance.state_from_json(info["state"])
    assert not term and not trunc


def test_tiles_episode_terminates_at_the_goal_with_the_hand_computed_return():
    env = cgym.make("tiles", "000000000")  # no tiles: start (1, 1), goal (5, 1)
    env.reset(seed=1)
    total, steps = 0.0, 0
    while True:
        obs, r, term, trunc, info = env.step(RIGHT)
        total += r
        steps += 1
        if term or trunc:
            break
    assert (steps, term, trunc) == (4, True, False)
    assert obs == env.terminal_observation == env.observation_space.n - 1
    assert total == pytest.approx(-4 / TILES_NORM, abs=1e-12)
    with pytest.raises(RuntimeError, match="call reset"):
        env.step(RIGHT)


def test_truncation_after_max_steps_and_action_order():
    env = cgym.make("tiles", 0, max_steps=3)
    env.reset()
    _, _, _, _, info = env.step(UP)  # action 0 is "up": y + 1
    assert info["state"]["agent"] == [1, 2] and info["action"] == "up"
    _, _, _, trunc, info = env.step(PICKUP)  # a no-op that still costs a step
    assert info["state"]["agent"] == [1, 2] and not trunc
    assert info["features"].tolist() == [0, 0, 1]
    _, _, term, trunc, _ = env.step(DOWN)
    assert (term, trunc) == (False, True)
    assert env.domain.actions == ("up", "down", "left", "right", "pickup", "dropoff")


def test_seeded_random_starts_are_reproducible_and_vary():
    env = cgym.make("skateboard", "111", start_state="random")
    first = [env.reset(seed=s)[0] for s in range(12)]
    again = [env.reset(seed=s)[0] for s in range(12)]
    assert first == again
    assert len(set(first)) > 3
    fixed = cgym.make("skateboard", "111")
    assert {fixed.reset(seed=s)[0] for s in range(5)} == {0}
    start = {"agent": [2, 2], "skateboard": [2, 2], "carrying": True}
    obs, info = fixed.reset(options={"start_state": start})
    assert info["state"] == start and fixed.state_of(obs) == (2, 2, 2, 2, 1)


def test_render_modes_show_the_agent_where_it_is():
    env = cgym.make("delivery", "000001", render_mode="ansi")  # station at (4, 3)
    env.reset()
    text = env.render()
    rows = text.strip().splitlines()[1:-1]
    assert rows[-1][1 + 1] == "@"  # agent at (2, 1): bottom row, column 2
    assert rows[0][4] == "h"  # station at (4, 3): top row, column 4
    env = cgym.make("delivery", "000001", render_mode="rgb_array", cell_px=20)
    env.reset()
    env.step(UP)  # (2, 2)
    img = env.render()
    assert img.shape == (3 * 20 + 1, 4 * 20 + 1, 3) and img.dtype == np.uint8
    blue = np.all(img == np.array([0x62, 0x8D, 0xBE]), axis=-1)
    ys, xs = np.nonzero(blue)
    assert 20 <= xs.min() and xs.max() < 40 and 20 <= ys.min() and ys.max() < 40
    trail = np.array([int(st.TRAIL_COLOR[i : i + 2], 16) for i in (1, 3, 5)])
    assert np.all(img[50, 30] == trail)  # the trail's start dash in (2, 1)


def test_bad_arguments_get_clear_errors():
    with pytest.raises(ValueError, match="render_mode 'human' is not supported"):
        cgym.make("tiles", 0, render_mode="human")
    with pytest.raises(ValueError, match="this domain has 3 bits"):
        cgym.make("skateboard", [1, 0])
    with pytest.raises(ValueError, match="string of 0/1 bits"):
        cgym.make("skateboard", "12a")
    with pytest.raises(ValueError, match="not a reachable non-terminal state"):
        cgym.make("tiles", 0, start_state=(5, 1))  # the goal is terminal
    env = cgym.make("tiles", 0)
    env.reset()
    with pytest.raises(ValueError, match="not in Discrete"):
        env.step(6)


USER_DOMAIN = {
    "domain": {
        "name": "keys",
        "title": "Keys",
        "description": "a user domain",
        "width": 4,
        "height": 2,
        "discount": 1.0,
        "walls": [[2, 2]],
    },
    "cells": {"lava": [[3, 1]]},
    "agent": {"start": [1, 1]},
    "cargo": {"name": "key", "start": [1, 2]},
    "consumables": [{"name": "coin", "cell": [4, 2]}],
    "goal": {"agent_at": [4, 1]},
    "variants": [{"add_cells": {"lava": [[3, 2]]}}, {"switch_on": ["coin"]}],
    "features": [
        {"name": "burn", "label": "Lava", "weight": -2.0, "when": {"leaves_cells": "lava"}},
        {"name": "coin", "label": "Coin", "weight": 1.0, "when": {"consumes": "coin"}},
        {"name": "step", "label": "Step", "weight": -1.0},
    ],
    "beliefs": {"prior": [[0, 0, -1]], "posterior": [[-1, 0, 0], [0, 1, 0], [0, 0, -1]]},
}


def test_user_domains_get_environments_and_generic_pictures():
    from cfteach import domains

    dom = domains.from_dict(USER_DOMAIN, source="test-keys")
    env = gymnasium.make(cgym.ENV_ID, domain=dom, env_code="11", render_mode="ansi")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(env.unwrapped)
    env = cgym.make(dom, "11", render_mode="ansi")
    env.reset()
    rows = env.render().strip().splitlines()[1:-1]
    lava = st.cell_style("lava", 0).char
    key = st.object_style("key", "cargo").char
    coin = st.object_style("coin", "consumable").char
    assert rows == [f"|{key}#{lava}{coin}|", f"|@ {lava}G|"]
    env = cgym.make(dom, "11", render_mode="rgb_array", cell_px=20)
    env.reset()
    img = env.render()
    lava_rgb = [int(st.cell_style("lava", 0).color[i : i + 2], 16) for i in (1, 3, 5)]
    assert img[20 + 2, 40 + 2].tolist() == lava_rgb  # cell (3, 1), near its top-left corner


def test_tabular_P_matches_step_and_value_iteration_gives_the_hand_computed_return():
    env = cgym.make("tiles", "000000000")  # no tiles: the best return from (1, 1) is 4 steps
    P = env.P
    assert set(P) == set(range(env.observation_space.n))
    for obs in range(env.terminal_observation):
        for a in range(6):
            env.reset(options={"start_state": env.state_of(obs)})
            nxt, r, term, _, _ = env.step(a)
            assert P[obs][a] == [(1.0, nxt, r, term)]
    # plain value iteration over P (gamma = 1, all rewards negative: it converges)
    V = np.zeros(env.observation_space.n)
    for _ in range(100):
        V = np.array(
            [
                max(sum(p * (r + (0 if t else V[n])) for p, n, r, t in P[s][a]) for a in range(6))
                for s in range(len(V))
            ]
        )
    assert V[0] == pytest.approx(-4 / TILES_NORM, abs=1e-12)
    assert V[env.terminal_observation] == 0


def test_builtin_ids_are_registered():
    env = gymnasium.make("cfteach/Delivery-v0", env_code="000001", render_mode="ansi")
    assert env.unwrapped.domain.name == "delivery"
    assert env.unwrapped.instance.env_code == (0, 0, 0, 0, 0, 1)
    assert gymnasium.make("cfteach/Skateboard-v0", env_code=7).unwrapped.domain.name == "skateboard"
