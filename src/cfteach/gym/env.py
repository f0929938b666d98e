"""`GridEnv`: one cfteach domain as a `gymnasium.Env` (conventions in docs/rendering.md).

Two observation types, because the two kinds of user want different things:

- `"index"` (default): `Discrete(S + 1)` over one fixed instance, the toy-text convention
  (FrozenLake, Taxi) with `P[obs][action]` for tabular code; `S` means "terminal".
- `"state"`: `MultiDiscrete` vector `[env_code bits..., state ints...]` (the State tuple of
  docs/domains.md), the same space for every instance of the domain, so one environment (and
  one Minari dataset) can span instances: `reset(options={"env_code": ...})` switches instance
  and `env_code="random"` draws one per `reset(seed=...)`.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from enum import IntEnum
from typing import TYPE_CHECKING, Any

import gymnasium
import numpy as np
from gymnasium import spaces

if TYPE_CHECKING:
    from cfteach.render import Layout

OBSERVATION_TYPES = ("index", "state")

#: The study's keys (arrows, `p` pick up, `d` drop) as SDL2/pygame key codes, so
#: `gymnasium.utils.play.play(env, wait_on_player=True)` plays like the study's test games.
STUDY_KEYS: dict[str, int | str] = {
    "up": 0x40000052, "down": 0x40000051, "left": 0x40000050, "right": 0x4000004F,
    "pickup": "p", "dropoff": "d"}
#: `KeyboardEvent.key` names (what an `ActionSpec.key` holds) without a printable face, as
#: SDL2/pygame key codes; a one-character key stays that character.
SDL_KEYS: dict[str, int | str] = {
    "ArrowUp": 0x40000052, "ArrowDown": 0x40000051, "ArrowLeft": 0x40000050,
    "ArrowRight": 0x4000004F, "Enter": 13, "Escape": 27, "Backspace": 8, "Tab": 9, " ": " "}


def sdl_key(key: str) -> int | str:
    """An `ActionSpec.key` as `gymnasium.utils.play` takes it (ValueError if it has none)."""
    if key in SDL_KEYS:
        return SDL_KEYS[key]
    if len(key) == 1:
        return key.lower()
    raise ValueError(f"key {key!r} has no pygame equivalent (use a single character, "
                     f"or one of {', '.join(sorted(k for k in SDL_KEYS if k != ' '))})")


def _action_specs(domain: Any) -> tuple[Any, ...]:
    """The domain's ActionSpecs in action order (the built-ins' for objects without them)."""
    from cfteach.domains.spec import BUILTIN_ACTIONS

    return tuple(getattr(domain, "action_specs", None)
                 or (BUILTIN_ACTIONS[a] for a in domain.actions))


def _resolve_domain(domain: Any) -> Any:
    from cfteach import domains

    if isinstance(domain, str):
        return domains.load(domain)
    if not hasattr(domain, "instances"):
        raise TypeError(f"domain must be a name, a path or a cfteach Domain, got {domain!r}")
    return domain


def _env_key(env_code: Any, n_bits: int) -> int | tuple[int, ...]:
    """Accept an index, a bit sequence or a bit string such as "010"."""
    if isinstance(env_code, str):
        if not env_code or set(env_code) - {"0", "1"}:
            raise ValueError(f"env_code {env_code!r}: expected a string of 0/1 bits")
        env_code = tuple(int(c) for c in env_code)
    if isinstance(env_code, (int, np.integer)):
        return int(env_code)
    bits = tuple(int(b) for b in env_code)
    if len(bits) != n_bits:
        raise ValueError(f"env_code {list(bits)}: this domain has {n_bits} bits")
    return bits


def state_space_nvec(domain: Any) -> list[int]:
    """Sizes of the `"state"` observation's components: env bits, then the State tuple
    (agent x, y; cargo x, y (0 = absent), held; one present-bit per consumable)."""
    spec = domain.spec
    w, h = int(domain.width), int(domain.height)
    nvec = [2] * int(domain.n_bits) + [w + 1, h + 1]
    if spec.cargo is not None:
        nvec += [w + 1, h + 1, 2]
    return nvec + [2] * len(spec.consumables)


class GridEnv(gymnasium.Env):
    """Instances of a cfteach domain as a Gymnasium environment (see the module docstring).

    `env_code=None` is the domain's first instance (index 0, all variant bits off), so every
    registered ID works with no arguments; `"random"` (with `observation="state"`) draws an
    instance per reset.
    """

    metadata = {"render_modes": ["ansi", "rgb_array"], "render_fps": 4}
    action_space: spaces.Discrete  # one discrete action per domain action (gymnasium: Space)

    def __init__(
        self,
        domain: Any,
        env_code: Any = None,
        start_state: Any = None,
        render_mode: str | None = None,
        max_steps: int = 100,
        cell_px: int = 48,
        observation: str = "index",
    ) -> None:
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(
                f"render_mode {render_mode!r} is not supported; use one of "
                f"{self.metadata['render_modes']} or None"
            )
        if observation not in OBSERVATION_TYPES:
            raise ValueError(f"observation {observation!r} is not one of {OBSERVATION_TYPES}")
        if int(max_steps) < 1:
            raise ValueError(f"max_steps must be at least 1, got {max_steps}")
        self.domain = _resolve_domain(domain)
        self.observation_type = observation
        self.random_instance = isinstance(env_code, str) and env_code == "random"
        if self.random_instance and observation != "state":
            raise ValueError('env_code="random" needs observation="state" (the index '
                             "observation space differs between instances)")
        self.render_mode = render_mode
        self.max_steps = int(max_steps)
        self.cell_px = int(cell_px)
        self.feature_names = tuple(self.domain.feature_names)
        self.weights = np.asarray(self.domain.weights, dtype=float)
        self.action_meanings = list(self.domain.actions)
        # the members are the domain's actions, known only at run time, which mypy's
        # functional-Enum support cannot follow
        self.actions = IntEnum(  # type: ignore[misc]
            "Actions", {a: i for i, a in enumerate(self.action_meanings)}
        )
        self.action_space = spaces.Discrete(len(self.action_meanings))
        self._set_instance(self.domain.instance(
            0 if env_code is None or self.random_instance
            else _env_key(env_code, self.domain.n_bits)))
        if observation == "index":
            self.observation_space = spaces.Discrete(len(self._states) + 1)
        else:
            self.observation_space = spaces.MultiDiscrete(
                np.array(state_space_nvec(self.domain), dtype=np.int64))
        self._parse_start(start_state)  # fail early on a bad start
        self._default_start = start_state
        self._state = self.instance.initial_state
        self._done = False
        self._steps = 0
        self._trail: list[tuple[int, int]] = []

    # ------------------------------------------------------------------ helpers
    def _set_instance(self, instance: Any) -> None:
        self.instance = instance
        self._states = list(instance.states())
        self._index = {s: i for i, s in enumerate(self._states)}
        self.terminal_observation = len(self._states)
        self._layout: Layout | None = None
        self._P: dict[int, dict[int, list[tuple[float, int, float, bool]]]] | None = None

    def _parse_start(self, start: Any) -> Any:
        if start is None or (isinstance(start, str) and start == "random"):
            return start
        if isinstance(start, str):  # a JSON object, as Minari stores reset options
            try:
                start = json.loads(start)
            except json.JSONDecodeError:
                raise ValueError(f"start_state {start!r}: expected 'random', a State tuple "
                                 "or a JSON object") from None
        if isinstance(start, Mapping):
            start = self.instance.state_from_json(dict(start))
        start = tuple(int(v) for v in start)
        if start not in self._index:
            raise ValueError(
                f"start_state {start} is not a reachable non-terminal state of "
                f"{self.domain.name} instance {list(self.instance.env_code)}"
            )
        return start

    def _obs(self) -> Any:
        if self.observation_type == "state":
            return np.array([*self.instance.env_code, *self._state], dtype=np.int64)
        return self.terminal_observation if self._done else self._index[self._state]

    def state_of(self, observation: Any) -> Any:
        """The State behind an observation (None for the index type's terminal observation)."""
        if self.observation_type == "state":
            return tuple(int(v) for v in np.asarray(observation)[self.domain.n_bits:])
        if observation == self.terminal_observation:
            return None
        return self._states[int(observation)]

    def get_action_meanings(self) -> list[str]:
        """Action names in action order (the Atari/ALE convention; Minigrid has `actions`)."""
        return list(self.action_meanings)

    def get_keys_to_action(self) -> dict[tuple[Any, ...], int]:
        """Keys for `gymnasium.utils.play.play`: each action's declared key (`ActionSpec.key`;
        the built-ins: arrows, `p`, `d`) bound to its index in the domain's action order."""
        return {(sdl_key(spec.key),): i
                for i, spec in enumerate(_action_specs(self.domain))}

    @property
    def P(self) -> dict[int, dict[int, list[tuple[float, int, float, bool]]]]:  # noqa: N802
        """Transitions of the current instance in the toy-text convention (FrozenLake, Taxi):
        `P[obs][action] = [(1.0, next_obs, reward, terminated)]` over index observations; the
        terminal observation loops on itself with reward 0."""
        if self._P is None:
            table: dict[int, dict[int, list[tuple[float, int, float, bool]]]] = {}
            for i, st in enumerate(self._states):
                row = {}
                for a in range(self.action_space.n):
                    nxt, phi, terminal = self.instance.step(st, a)
                    obs = self.terminal_observation if terminal else self._index[nxt]
                    reward = float(self.weights @ np.asarray(phi, dtype=float))
                    row[a] = [(1.0, obs, reward, bool(terminal))]
                table[i] = row
            end = self.terminal_observation
            table[end] = {a: [(1.0, end, 0.0, True)] for a in range(self.action_space.n)}
            self._P = table
        return self._P

    @property
    def state(self) -> Any:
        """The current State tuple (after the goal: the terminal state reached)."""
        return self._state

    # ---------------------------------------------------------------- Env API
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Any, dict[str, Any]]:
        """Start an episode. `options`: `env_code` (observation="state" only, or the env's
        own instance) and `start_state` ("random", a State tuple, a JSON dict or its text)."""
        super().reset(seed=seed)
        options = dict(options or {})
        code = options.get("env_code")
        if code is not None:
            inst = self.domain.instance(_env_key(code, self.domain.n_bits))
            if inst is not self.instance:
                if self.observation_type != "state":
                    raise ValueError("reset(options={'env_code': ...}) switches instance only "
                                     'with observation="state"; make one env per instance')
                self._set_instance(inst)
        elif self.random_instance:
            self._set_instance(self.domain.instance(
                int(self.np_random.integers(len(self.domain.instances())))))
        start = self._parse_start(options.get("start_state", self._default_start))
        if start is None:
            state = self.instance.initial_state
        elif isinstance(start, str):  # "random"
            state = self._states[int(self.np_random.integers(len(self._states)))]
        else:
            state = start
        self._state, self._done, self._steps = state, False, 0
        self._trail = [(state[0], state[1])]
        return self._obs(), {"state": self.instance.state_to_json(state),
                             "env_code": "".join(map(str, self.instance.env_code))}

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        if not self.action_space.contains(action):
            raise ValueError(
                f"action {action!r} is not in {self.action_space} "
                f"(actions: {', '.join(self.domain.actions)})"
            )
        if self._done:
            raise RuntimeError("the episode has ended (goal reached); call reset()")
        nxt, phi, terminal = self.instance.step(self._state, int(action))
        phi = np.asarray(phi, dtype=float)
        reward = float(self.weights @ phi)
        self._state, self._done = nxt, bool(terminal)
        self._steps += 1
        cell = (nxt[0], nxt[1])
        if self._trail[-1] != cell:
            self._trail.append(cell)
        truncated = self._steps >= self.max_steps and not self._done
        info = {
            "features": phi,
            "state": self.instance.state_to_json(nxt),
            "action": self.domain.actions[int(action)],
        }
        return self._obs(), reward, self._done, truncated, info

    def render(self) -> Any:
        if self.render_mode is None:
            gymnasium.logger.warn("render() called without a render_mode; returning None")
            return None
        from cfteach import render

        if self._layout is None:
            self._layout = render.layout_from_instance(self.instance)
        scene = render.scene_from_state_json(
            self._layout, self.instance.state_to_json(self._state), self._trail, done=self._done
        )
        if self.render_mode == "ansi":
            return render.to_text(scene) + "\n"
        return render.to_rgb_array(scene, self.cell_px)
