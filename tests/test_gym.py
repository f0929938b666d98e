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
        check_env(cgym.make(dom, "random", observation="state", render_mode="ansi"))
        check_env(gymnasium.make(cgym.ENV_ID, domain=dom).unwrapped)  # no env_code: first
    assert cgym.state_space_nvec(dom) == [2, 2, 5, 3, 5, 3, 2, 2]  # bits, agent, key, coin
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


# ------------------------------------------------- Gymnasium conventions (issue 15, part 1)
@pytest.mark.parametrize("env_id", sorted(cgym.BUILTIN_IDS.values()))
def test_registered_ids_work_without_arguments_and_pass_the_checker(env_id):
    env = gymnasium.make(env_id)  # used to raise TypeError: missing 'env_code'
    base = env.unwrapped
    assert base.instance.index == 0 and base.instance.env_code == (0,) * base.domain.n_bits
    assert env.reset(seed=3)[1]["state"] == base.instance.state_to_json(
        base.instance.initial_state)
    assert env.spec.id == env_id and env.spec.max_episode_steps == cgym.MAX_EPISODE_STEPS
    assert base.metadata["render_fps"] > 0
    assert base.action_meanings == base.get_action_meanings() == list(base.domain.actions)
    assert base.actions.pickup == 4 and base.actions(3).name == "right"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(base)
        check_env(gymnasium.make(env_id, observation="state", env_code="random").unwrapped)


def test_make_sets_the_spec_so_the_checker_does_not_warn():
    env = cgym.make("tiles", 0)
    assert env.spec is not None and env.spec.id == cgym.ENV_ID
    assert env.spec.kwargs["domain"] == "tiles" and env.spec.max_episode_steps == 100
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # "not having a spec" was a warning before
        check_env(env)


def test_time_limit_of_the_spec_truncates_like_the_env():
    env = gymnasium.make("cfteach/Tiles-v0", max_episode_steps=3, max_steps=3)
    env.reset()
    for _ in range(2):
        assert env.step(0)[3] is False
    assert env.step(0)[3] is True


def _fresh_python(code):
    import subprocess
    import sys

    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=False)
    assert done.returncode == 0, done.stderr
    return done.stdout.split()


def test_ids_resolve_without_importing_cfteach_gym_first():
    out = _fresh_python(
        "import sys, gymnasium\n"
        "env = gymnasium.make('cfteach.gym:cfteach/Skateboard-v0')\n"
        "print('cfteach.gym' in sys.modules, env.spec.id, env.unwrapped.domain.name)")
    assert out == ["True", "cfteach/Skateboard-v0", "skateboard"]


def test_the_gymnasium_envs_entry_point_registers_the_ids():
    out = _fresh_python(
        "from importlib.metadata import entry_points\n"
        "import gymnasium\n"
        "(ep,) = [e for e in entry_points(group='gymnasium.envs') if e.name == 'cfteach']\n"
        "ep.load()()\n"
        "print(sorted(i for i in gymnasium.registry if i.startswith('cfteach/')))")
    assert out == ["['cfteach/Delivery-v0',", "'cfteach/GridWorld-v0',",
                   "'cfteach/Skateboard-v0',", "'cfteach/Tiles-v0']"]


def test_state_observations_span_instances_and_restart_any_episode():
    env = cgym.make("delivery", "random", observation="state")
    codes = set()
    for seed in range(8):
        obs, info = env.reset(seed=seed)
        assert env.observation_space.contains(obs)
        bits, state = obs[:6], tuple(obs[6:])
        assert "".join(map(str, bits)) == info["env_code"]
        assert state == env.instance.initial_state == env.state_of(obs)
        codes.add(info["env_code"])
    assert len(codes) > 3
    assert [env.reset(seed=s)[1]["env_code"] for s in range(8)] == [
        env.reset(seed=s)[1]["env_code"] for s in range(8)]
    # what a Minari episode stores: the options as strings
    start = '{"agent": [3, 1], "passenger": [4, 2], "carrying": false, "station": false}'
    obs, info = env.reset(options={"env_code": "000010", "start_state": start})
    assert obs.tolist() == [0, 0, 0, 0, 1, 0, 3, 1, 4, 2, 0, 0]
    obs, r, *_ = env.step(RIGHT)  # leaves the mud at (3, 1): mud + step
    assert obs.tolist()[6:8] == [4, 1] and r == pytest.approx(-4 / DELIVERY_NORM, abs=1e-12)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(cgym.make("skateboard", "101", observation="state"))


def test_index_observations_refuse_to_switch_instance():
    env = cgym.make("delivery", "000010")
    env.reset(options={"env_code": "000010"})  # its own instance is fine
    with pytest.raises(ValueError, match='switches instance only with observation="state"'):
        env.reset(options={"env_code": "000001"})
    with pytest.raises(ValueError, match='needs observation="state"'):
        cgym.make("delivery", "random")
    with pytest.raises(ValueError, match="observation 'pixels' is not one of"):
        cgym.make("delivery", observation="pixels")
    with pytest.raises(ValueError, match="expected 'random', a State tuple or a JSON object"):
        env.reset(options={"start_state": "{not json"})


def _play_key_codes(env):
    """The key-code table `gymnasium.utils.play.play` builds from get_keys_to_action()."""
    return {tuple(sorted(ord(k) if isinstance(k, str) else k for k in combo)): a
            for combo, a in env.get_keys_to_action().items()}


def test_keyboard_play_uses_the_study_keys():
    env = cgym.make("delivery", "000000", render_mode="rgb_array")
    keys = _play_key_codes(env)
    k_up, k_down, k_left, k_right = 1073741906, 1073741905, 1073741904, 1073741903  # pygame
    assert keys == {(k_up,): UP, (k_down,): DOWN, (k_left,): LEFT, (k_right,): RIGHT,
                    (ord("p"),): PICKUP, (ord("d"),): DROPOFF}
    env.reset()  # agent (2, 1), package (4, 2): right, right, up, p picks it up
    for code in (k_right, k_right, k_up, ord("p")):
        *_, info = env.step(keys[(code,)])
    assert info["state"]["carrying"] is True
    # a user domain listing its actions in another order keeps the keys on the names
    from cfteach import domains

    data = {**USER_DOMAIN, "domain": {**USER_DOMAIN["domain"],
                                      "actions": ["right", "pickup", "up", "left"]}}
    dom = domains.from_dict(data, source="test-keys-order")
    user = _play_key_codes(cgym.make(dom, "00"))
    assert user == {(k_right,): 0, (ord("p"),): 1, (k_up,): 2, (k_left,): 3}


def test_declared_actions_give_the_space_the_meanings_and_the_keys():
    """A domain declaring a seventh action (`exit` on "x", `stay` on "w") gets a Discrete(8)
    space, the names in order and its keys in `get_keys_to_action`."""
    from actions_fixtures import EXIT, STAY, domain_with

    dom = domain_with(EXIT, STAY)
    env = cgym.make(dom, "000000")
    assert env.action_space.n == 8
    assert env.get_action_meanings()[-2:] == ["exit", "stay"]
    keys = _play_key_codes(env)
    assert keys[(ord("x"),)] == 6 and keys[(ord("w"),)] == 7
    assert keys[(ord("p"),)] == PICKUP
    env.reset()
    *_, info = env.step(6)
    assert info["action"] == "exit"


def test_a_key_without_a_pygame_code_is_named():
    from actions_fixtures import domain_with
    from cfteach.domains import ActionSpec

    env = cgym.make(domain_with(ActionSpec("jump", "jump", "PageUp", "stay")), "000000")
    with pytest.raises(ValueError, match="key 'PageUp' has no pygame equivalent"):
        env.get_keys_to_action()
