"""A domain with a declared seventh action, `exit` on key "x", for the display-side tests.

Built from delivery with `dataclasses.replace` (a domain file cannot declare actions yet on
this branch). `ExitDomain` wraps its instances so that `exit` ends the episode (the state
tuple unchanged, the features the engine fires for it), as an `exit` effect does.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from cfteach.domains import ActionSpec, Domain, load

EXIT = ActionSpec("exit", "leave the game", "x", "exit")
STAY = ActionSpec("stay", "wait a moment", "w", "stay")


def domain_with(*extra: ActionSpec, name: str = "delivery_exit",
                base: str = "delivery") -> Domain:
    """`base` (delivery) plus `extra` actions after its own (a no-op in the engine)."""
    dom = load(base)
    spec = dataclasses.replace(dom.spec, name=name,
                               actions=(*dom.actions, *(a.name for a in extra)),
                               action_specs=(*dom.action_specs, *extra))
    return Domain.from_spec(spec)


class ExitInstance:
    """An instance whose `exit` action moves to the terminal state."""

    def __init__(self, inst: Any, exit_index: int) -> None:
        self._inst = inst
        self._exit = exit_index

    def __getattr__(self, name: str) -> Any:
        return getattr(self._inst, name)

    def step(self, state: tuple, action: int) -> tuple:
        nxt, phi, term = self._inst.step(state, action)
        if action == self._exit and not self._inst.is_terminal(state):
            return state, phi, True
        return nxt, phi, term


class ExitDomain:
    """`domain_with(EXIT)` whose instances end the episode on `exit` (the `Domain` contract
    the study builder reads: name, actions, action_specs, features, weights, instances)."""

    def __init__(self, name: str = "delivery_exit") -> None:
        self._dom = domain_with(EXIT, name=name)
        idx = self._dom.actions.index("exit")
        self._instances = [ExitInstance(i, idx) for i in self._dom.instances()]

    def __getattr__(self, name: str) -> Any:
        return getattr(self._dom, name)

    def instances(self) -> list[ExitInstance]:
        return list(self._instances)
