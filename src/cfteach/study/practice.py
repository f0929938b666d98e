"""A small cargo gridworld following the `cfteach.domains.Instance` contract.

It serves as the study's practice game ("pick up the green pentagon and drop it at the
purple star" with an orange diamond that gives energy) and as a compact stand-in domain for
tests of the platform.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from cfteach.domains import ACTIONS  # the built-in domains' action order

__all__ = ["ACTIONS", "CargoGrid", "PRACTICE", "PRACTICE_START_ENERGY", "PRACTICE_WEIGHTS"]
_MOVES = {0: (0, 1), 1: (0, -1), 2: (-1, 0), 3: (1, 0)}

Cell = tuple[int, int]


@dataclass(frozen=True)
class CargoGrid:
    """Grid with walls, optional cargo + destination or goal cell, cost cells, one consumable.

    Features, in order: one per `leave_cells` entry (fires when moving out of such a cell),
    then the consumable (fires when leaving its cell while it is present), then `step`.
    """

    width: int
    height: int
    start: Cell
    walls: frozenset[Cell] = frozenset()
    cargo: Cell | None = None
    destination: Cell | None = None
    goal: Cell | None = None
    leave_cells: tuple[tuple[str, frozenset[Cell]], ...] = ()
    consumable: tuple[str, Cell] | None = None
    cargo_name: str = "package"
    consumable_initially: bool = True
    styles: dict[str, str] = field(default_factory=dict, compare=False, hash=False)

    @property
    def feature_names(self) -> tuple[str, ...]:
        names = [n for n, _ in self.leave_cells]
        if self.consumable:
            names.append(self.consumable[0])
        return (*names, "step")

    @property
    def initial_state(self) -> tuple[int, ...]:
        cx, cy = self.cargo or (0, 0)
        present = self.consumable is not None and self.consumable_initially
        return (*self.start, cx, cy, 0, int(present))

    def step(self, state: tuple[int, ...], a: int) -> tuple[tuple[int, ...], list[int], bool]:
        ax, ay, cx, cy, carrying, present = state
        nx, ny = ax, ay
        if a in _MOVES:
            dx, dy = _MOVES[a]
            tx, ty = ax + dx, ay + dy
            if 1 <= tx <= self.width and 1 <= ty <= self.height and (tx, ty) not in self.walls:
                nx, ny = tx, ty
                if carrying:
                    cx, cy = nx, ny
        elif a == 4 and self.cargo and not carrying and (ax, ay) == (cx, cy):
            carrying = 1
        elif a == 5 and carrying:
            carrying = 0
        moved = (nx, ny) != (ax, ay)
        phi = [int(moved and (ax, ay) in cells) for _, cells in self.leave_cells]
        if self.consumable:
            fired = int(bool(present) and moved and (ax, ay) == self.consumable[1])
            phi.append(fired)
            if fired:
                present = 0
        phi.append(1)
        nxt = (nx, ny, cx, cy, carrying, present)
        return nxt, phi, self.is_terminal(nxt)

    def is_terminal(self, s: tuple[int, ...]) -> bool:
        if self.destination is not None:
            return not s[4] and (s[2], s[3]) == self.destination
        return self.goal is not None and (s[0], s[1]) == self.goal

    def state_to_json(self, s: tuple[int, ...]) -> dict:
        out: dict = {"agent": [s[0], s[1]]}
        if self.cargo:
            out[self.cargo_name] = [s[2], s[3]]
            out["carrying"] = bool(s[4])
        if self.consumable:
            out[self.consumable[0]] = bool(s[5])
        return out

    def state_from_json(self, d: dict) -> tuple[int, ...]:
        cx, cy = d.get(self.cargo_name) or (0, 0)
        present = int(bool(d.get(self.consumable[0], True))) if self.consumable else 0
        return (*d["agent"], cx, cy, int(bool(d.get("carrying", False))), present)

    def study_layout(self) -> dict:
        """The static picture of this game, in the page's layout format (see docs/study.md)."""
        st = self.styles
        regions = [{"name": n, "style": st.get(n, n), "cells": sorted(map(list, c))}
                   for n, c in self.leave_cells]
        markers = []
        if self.goal:
            markers.append({"name": "goal", "style": st.get("goal", "goal"),
                            "cell": list(self.goal)})
        if self.destination:
            markers.append({"name": "destination", "style": st.get("destination", "destination"),
                            "cell": list(self.destination)})
        consumables = []
        if self.consumable and self.consumable_initially:
            n, c = self.consumable
            consumables.append({"key": n, "style": st.get(n, n), "cell": list(c)})
        cargo = ({"key": self.cargo_name, "style": st.get(self.cargo_name, self.cargo_name)}
                 if self.cargo else None)
        return {"width": self.width, "height": self.height,
                "walls": sorted(map(list, self.walls)), "regions": regions,
                "markers": markers, "consumables": consumables, "cargo": cargo}


#: The practice game: every action costs 5% energy, moving out of the diamond gives 10%.
PRACTICE = CargoGrid(
    width=6, height=3, start=(1, 2), walls=frozenset({(3, 2), (3, 3)}),
    cargo=(2, 3), destination=(6, 3), consumable=("diamond", (4, 1)),
    cargo_name="pentagon",
    styles={"pentagon": "pentagon", "destination": "star", "diamond": "diamond"},
)
PRACTICE_WEIGHTS = (10.0, -5.0)  # energy change per (diamond, step)
PRACTICE_START_ENERGY = 100.0
