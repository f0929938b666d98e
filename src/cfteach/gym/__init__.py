"""Every cfteach domain as a `gymnasium.Env`, so its instances reach other RL/IRL tools.

Conventions (docs/rendering.md has the full list):

- **IDs**: `cfteach/Delivery-v0`, `cfteach/Tiles-v0`, `cfteach/Skateboard-v0` (domain preset)
  and `cfteach/GridWorld-v0` (pass `domain=`: a name, a domain file or a Domain). With no
  arguments an ID gives the domain's first instance from its initial state; `env_code=`,
  `start_state=` and `observation="state"` are the options. Each spec has
  `max_episode_steps=100`.
- **Registration**: importing `cfteach.gym` registers the IDs; `gymnasium.make(
  "cfteach.gym:cfteach/Delivery-v0")` imports it for you (Gymnasium 1.x loads no plugins
  by itself; the `gymnasium.envs` entry point in pyproject serves older loaders).
- **Actions**: `Discrete(A)` in the domain file's order; `env.unwrapped.action_meanings`,
  `get_action_meanings()` and the `Actions` IntEnum `env.unwrapped.actions` name them.
- **Observations**: see `GridEnv` (`"index"`: toy-text `Discrete`; `"state"`: env bits +
  State vector, the same space for all instances).
- **Reward**: `w* . phi(s, a, s')` with the domain's unit-norm `w*`; `info["features"]` is phi.
- **Episode end**: `terminated` at the goal; `truncated` after `max_steps` steps.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import gymnasium

from cfteach.gym.env import OBSERVATION_TYPES, STUDY_KEYS, GridEnv, state_space_nvec

__all__ = ["BUILTIN_IDS", "ENV_ID", "GridEnv", "MAX_EPISODE_STEPS", "OBSERVATION_TYPES",
           "STUDY_KEYS", "env_id", "make", "register_envs", "state_space_nvec"]

ENV_ID = "cfteach/GridWorld-v0"
MAX_EPISODE_STEPS = 100
BUILTIN_IDS = {
    "delivery": "cfteach/Delivery-v0",
    "tiles": "cfteach/Tiles-v0",
    "skateboard": "cfteach/Skateboard-v0",
}


def env_id(domain_name: str) -> str:
    """The registered ID of a built-in domain, else the generic `cfteach/GridWorld-v0`."""
    return BUILTIN_IDS.get(domain_name, ENV_ID)


def make(
    domain: Any,
    env_code: int | str | Sequence[int] | None = None,
    start_state: Any = None,
    render_mode: str | None = None,
    *,
    max_steps: int = MAX_EPISODE_STEPS,
    cell_px: int = 48,
    observation: str = "index",
) -> GridEnv:
    """A `GridEnv` for `domain` (a name, a path or a Domain), made through Gymnasium's
    registry so that `env.spec` is set (the checker and recorders need it).

    `env_code` is the instance's bits (a list or a string like "010"), its index, None (the
    first instance) or "random" (with `observation="state"`).
    """
    modes = GridEnv.metadata["render_modes"]
    if render_mode is not None and render_mode not in modes:  # before Gymnasium wraps it
        raise ValueError(f"render_mode {render_mode!r} is not supported; use one of "
                         f"{modes} or None")
    env = gymnasium.make(
        ENV_ID, domain=domain, env_code=env_code, start_state=start_state,
        render_mode=render_mode, max_steps=max_steps, cell_px=cell_px,
        observation=observation, max_episode_steps=max_steps, disable_env_checker=True,
    )
    base = env.unwrapped
    if not isinstance(base, GridEnv):  # ENV_ID is registered to GridEnv (register_envs)
        raise TypeError(f"{ENV_ID} made a {type(base).__name__}, not a GridEnv")
    base.spec = env.spec  # the outer spec also records max_episode_steps
    return base


def register_envs() -> None:
    """Register the cfteach IDs with Gymnasium (idempotent; also the entry point's target)."""
    if ENV_ID not in gymnasium.registry:
        gymnasium.register(id=ENV_ID, entry_point="cfteach.gym:GridEnv",
                           max_episode_steps=MAX_EPISODE_STEPS)
    for name, eid in BUILTIN_IDS.items():
        if eid not in gymnasium.registry:
            gymnasium.register(id=eid, entry_point="cfteach.gym:GridEnv",
                               kwargs={"domain": name}, max_episode_steps=MAX_EPISODE_STEPS)


register_envs()
