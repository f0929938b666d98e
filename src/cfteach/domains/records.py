"""The records a domain file becomes (`DomainSpec` and its parts), the built-in actions, and
the error a malformed file raises. `cfteach.domains.spec` parses files into these; the engine
(`domains/dynamics.py`, `domains/model.py`) reads them, so they sit below both.
"""

from __future__ import annotations

from dataclasses import dataclass

ACTIONS: tuple[str, ...] = ("up", "down", "left", "right", "pickup", "dropoff")
MOVES: dict[str, tuple[int, int]] = {
    "up": (0, 1), "down": (0, -1), "left": (-1, 0), "right": (1, 0)}
INTERACT: tuple[str, ...] = ("pickup", "dropoff")

#: What an action does to the state. ``move`` shifts the agent by its delta; ``pickup`` and
#: ``dropoff`` act on the cargo; ``exit`` ends the episode from any non-terminal state;
#: ``stay`` leaves the state unchanged.
ACTION_EFFECTS: tuple[str, ...] = ("move", "pickup", "dropoff", "exit", "stay")


@dataclass(frozen=True)
class ActionSpec:
    """One action of a domain, in the domain's action order (the order breaks ties).

    `key` is the keyboard key the study app binds (a `KeyboardEvent.key` value such as
    ``"ArrowUp"`` or ``"x"``) and `label` the words shown beside it; the renderer and the
    Gymnasium environment read the same record.
    """

    name: str
    label: str
    key: str
    effect: str
    delta: tuple[int, int] | None = None  # for effect "move"


#: The built-in actions, as a domain file that lists action names gets them.
BUILTIN_ACTIONS: dict[str, ActionSpec] = {
    "up": ActionSpec("up", "move up", "ArrowUp", "move", (0, 1)),
    "down": ActionSpec("down", "move down", "ArrowDown", "move", (0, -1)),
    "left": ActionSpec("left", "move left", "ArrowLeft", "move", (-1, 0)),
    "right": ActionSpec("right", "move right", "ArrowRight", "move", (1, 0)),
    "pickup": ActionSpec("pickup", "pick up", "p", "pickup"),
    "dropoff": ActionSpec("dropoff", "drop", "d", "dropoff"),
}

Cell = tuple[int, int]

#: Demonstrations per curriculum when a domain file has no ``[teaching] max_demos``.
DEFAULT_MAX_DEMOS = 5


class DomainFileError(ValueError):
    """A domain file (or dict) is malformed; the message names file, key path and problem."""

    def __init__(self, source: str, key: str, problem: str) -> None:
        self.source = source
        self.key = key
        self.problem = problem
        where = f"{source}: {key}" if key else source
        super().__init__(f"{where}: {problem}")


@dataclass(frozen=True)
class Condition:
    """One conjunction of per-transition tests; unset fields are not tested."""

    actions: frozenset[str] | None = None
    moved: bool | None = None
    carrying: bool | None = None
    from_cells: str | None = None
    leaves_cells: str | None = None
    consumes: str | None = None
    to_cells: str | None = None  # the agent moved and its cell in s' is in the set
    cargo_at: frozenset[Cell] | str | None = None  # cells, or a cell set, holding the cargo in s
    negated: tuple[Condition, ...] = ()  # `not = {...}`: none of these may hold


@dataclass(frozen=True)
class FeatureSpec:
    name: str
    label: str
    weight: float
    any_of: tuple[Condition, ...]  # OR of conjunctions; empty tuple = always fires
    unless: tuple[int, ...]  # indices of earlier features that suppress this one


@dataclass(frozen=True)
class VariantSpec:
    name: str
    add_cells: tuple[tuple[str, tuple[Cell, ...]], ...]
    switch_on: tuple[str, ...]


@dataclass(frozen=True)
class CargoSpec:
    name: str
    start: Cell
    blocked_cells_when_carried: str | None


@dataclass(frozen=True)
class DomainSpec:
    """The validated content of a domain file, before instances are built."""

    source: str
    name: str
    title: str
    description: str
    reference_name: str | None
    width: int
    height: int
    discount: float
    actions: tuple[str, ...]
    walls: frozenset[Cell]
    cells: tuple[tuple[str, tuple[Cell, ...]], ...]  # default content of each named set
    agent_start: Cell
    cargo: CargoSpec | None
    consumables: tuple[tuple[str, Cell], ...]
    goal_kind: str  # "agent_at" or "cargo_delivered_at"
    goal: Cell
    variants: tuple[VariantSpec, ...]
    features: tuple[FeatureSpec, ...]
    prior: tuple[tuple[int, ...], ...]
    posterior: tuple[tuple[int, ...], ...]
    max_demos: int = DEFAULT_MAX_DEMOS  # [teaching] max_demos: demonstrations per curriculum
    action_specs: tuple[ActionSpec, ...] = ()  # one per action, same order as `actions`
    known: tuple[str, ...] = ()  # [beliefs] known: features whose weight the learner knows

    def __post_init__(self) -> None:
        if not self.action_specs:
            object.__setattr__(self, "action_specs",
                               tuple(BUILTIN_ACTIONS[a] for a in self.actions))
