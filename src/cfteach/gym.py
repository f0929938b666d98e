"""Every domain instance as a `gymnasium.Env`, so cfteach domains reach other RL/IRL tools.

Conventions (also in docs/rendering.md):

- **Actions**: `Discrete(A)`; action `i` is the `i`-th action of the domain in its file's order
  (built-in domains: up, down, left, right, pickup, dropoff).
- **Observations**: `Discrete(S + 1)`; `i < S` is the index of the state in
  `Instance.states()` (the reachable non-terminal states, BFS order, initial state first) and
  `S` stands for "terminal" (the episode has ended). `info["state"]` always carries the full
  state in its JSON form (docs/schemas.md).
- **Reward**: `w* . phi(s, a, s')` with the domain's unit-norm `w*`; `info["features"]` is `phi`.
- **Start**: `start_state=None` starts every episode in the instance's initial state;
  `start_state="random"` draws a reachable state with the env's seeded generator
  (`reset(seed=...)` makes it reproducible); a State tuple or JSON dict fixes the start.
  `reset(options={"start_state": ...})` overrides it for one episode.
- **Episode end**: `terminated` when the goal is reached; `truncated` after `max_steps`
  steps (default 100).
- **Tabular view**: `env.unwrapped.P[obs][action] = [(1.0, next_obs, reward, terminated)]`,
  the toy-text convention (FrozenLake, Taxi) that tabular RL code expects.
- **Rendering**: `ansi` (one character per cell, see `cfteach.render.text`) and `rgb_array`
  (the study's pictures, `cell_px` pixels per cell), both with the episode's trail.

`gymnasium.make("cfteach/GridWorld-v0", domain="tiles", env_code="000000000")` works too, and
so do `cfteach/Delivery-v0`, `cfteach/Tiles-v0`, `cfteach/Skateboard-v0` (domain preset).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces

ENV_ID = "cfteach/GridWorld-v0"


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


class GridEnv(gymnasium.Env):
    """One instance of a cfteach domain as a Gymnasium environment (see module docstring)."""

    metadata = {"render_modes": ["ansi", "rgb_array"], "render_fps": 4}

    def __init__(
        self,
        domain: Any,
        env_code: Any,
        start_state: Any = None,
        render_mode: str | None = None,
        max_steps: int = 100,
        cell_px: int = 48,
    ) -> None:
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(
                f"render_mode {render_mode!r} is not supported; use one of "
                f"{self.metadata['render_modes']} or None"
            )
        if int(max_steps) < 1:
            raise ValueError(f"max_steps must be at least 1, got {max_steps}")
        self.domain = _resolve_domain(domain)
        self.instance = self.domain.instance(_env_key(env_code, self.domain.n_bits))
        self.render_mode = render_mode
        self.max_steps = int(max_steps)
        self.cell_px = int(cell_px)
        self.feature_names = tuple(self.domain.feature_names)
        self.weights = np.asarray(self.domain.weights, dtype=float)
        self._states = list(self.instance.states())
        self._index = {s: i for i, s in enumerate(self._states)}
        self.terminal_observation = len(self._states)
        self.action_space = spaces.Discrete(len(self.domain.actions))
        self.observation_space = spaces.Discrete(len(self._states) + 1)
        self._default_start = self._parse_start(start_state)
        self._layout = None
        self._P: dict[int, dict[int, list[tuple[float, int, float, bool]]]] | None = None
        self._state = self.instance.initial_state
        self._done = False
        self._steps = 0
        self._trail: list[tuple[int, int]] = []

    # ------------------------------------------------------------------ helpers
    def _parse_start(self, start: Any) -> Any:
        if start is None or (isinstance(start, str) and start == "random"):
            return start
        if isinstance(start, Mapping):
            start = self.instance.state_from_json(dict(start))
        start = tuple(int(v) for v in start)
        if start not in self._index:
            raise ValueError(
                f"start_state {start} is not a reachable non-terminal state of "
                f"{self.domain.name} instance {list(self.instance.env_code)}"
            )
        return start

    def _obs(self) -> int:
        return self.terminal_observation if self._done else self._index[self._state]

    def state_of(self, observation: int) -> Any:
        """The State behind an observation index (None for the terminal observation)."""
        if observation == self.terminal_observation:
            return None
        return self._states[int(observation)]

    @property
    def P(self) -> dict[int, dict[int, list[tuple[float, int, float, bool]]]]:  # noqa: N802
        """Transitions in the toy-text convention (FrozenLake, Taxi): `P[obs][action] =
        [(1.0, next_obs, reward, terminated)]`, for tabular tools; the terminal observation
        loops on itself with reward 0."""
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
    ) -> tuple[int, dict[str, Any]]:
        super().reset(seed=seed)
        start = self._default_start
        if options and "start_state" in options:
            start = self._parse_start(options["start_state"])
        if start is None:
            state = self.instance.initial_state
        elif isinstance(start, str):  # "random"
            state = self._states[int(self.np_random.integers(len(self._states)))]
        else:
            state = start
        self._state, self._done, self._steps = state, False, 0
        self._trail = [(state[0], state[1])]
        return self._obs(), {"state": self.instance.state_to_json(state)}

    def step(self, action: Any) -> tuple[int, float, bool, bool, dict[str, Any]]:
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


def make(
    domain: Any,
    env_code: int | str | Sequence[int],
    start_state: Any = None,
    render_mode: str | None = None,
    *,
    max_steps: int = 100,
    cell_px: int = 48,
) -> GridEnv:
    """A Gymnasium environment for one instance of `domain` (a name, a path or a Domain).

    `env_code` is the instance's bits (a list or a string like "010") or its index.
    """
    return GridEnv(domain, env_code, start_state, render_mode, max_steps, cell_px)


BUILTIN_IDS = {
    "delivery": "cfteach/Delivery-v0",
    "tiles": "cfteach/Tiles-v0",
    "skateboard": "cfteach/Skateboard-v0",
}


def _register() -> None:
    if ENV_ID not in gymnasium.registry:
        gymnasium.register(id=ENV_ID, entry_point="cfteach.gym:GridEnv")
    for name, env_id in BUILTIN_IDS.items():
        if env_id not in gymnasium.registry:
            gymnasium.register(
                id=env_id, entry_point="cfteach.gym:GridEnv", kwargs={"domain": name}
            )


_register()
